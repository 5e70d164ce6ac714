"""Applying the verdict to a diagnosis' findings (the tests themselves are in `checks`).

- `arbiter`: findings whose modelling does not lower the grouped cross-validated RMS are
  rejected; when the model with the rest is worse out of sample than geometry alone, every
  finding is rejected and the final model is the geometry;
- `carried`: findings that rest on one or two records (`checks.carried_by`);
- `misspecification`: findings whose own variable still shows structure (`checks.misspecified`)
  are `low` confidence; `twins`: findings the gate found indistinguishable from another
  library candidate are `medium` and list it; `look_alike_cap`: a finding the data can hardly tell
  from another candidate (its `look_alikes`: a swap the fit cannot reject at the diagnosis's level, or one
  explaining nearly all the finding explains) is never `high` — the label agrees with the text that says so.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pipeline.diagnose.inference import resampling
from pipeline.diagnose.verdict import checks


@dataclass(frozen=True)
class Final:
    """The final model's findings (dicts), their library indices, fitted contributions (n, k),
    columns of design A, residual r_final and cross-validation residuals."""

    findings: list
    accepted: list
    contributions: list
    col_of: dict
    A: np.ndarray
    r_final: np.ndarray
    after_cv: np.ndarray


def arbiter(fin: Final, folds, Jf: np.ndarray, r: np.ndarray,
            before_cv: np.ndarray) -> tuple[Final, list, bool, float]:
    """(final model kept, rejected findings, worse than geometry?, CV RMS with every selected finding)."""
    all_cv = resampling.rms(fin.after_cv)
    fds = fin.findings
    rej = [j for j, fd in enumerate(fds) if fd["evidence"]["cv_rms_after_m"] >= fd["evidence"]["cv_rms_before_m"]]
    drop = np.array([c for j in rej for c in fin.col_of[fin.accepted[j]]], int)
    A_k, r_k = checks.linearised_subset(fin.A, fin.r_final, drop, [fin.contributions[j] for j in rej])
    cv_k = resampling.holdout(A_k, r_k, folds) if rej else fin.after_cv
    worse = bool(fds) and len(rej) < len(fds) and resampling.rms(cv_k) > resampling.rms(before_cv)
    if worse:
        rej = list(range(len(fds)))
    if not rej:
        return fin, [], False, all_cv
    why = ("the model with the selected effects is worse out of sample than geometry alone" if worse else
           "modelling it does not lower the grouped cross-validated RMS")
    rejected = [{**fds[j], "confidence": "rejected", "note": why} for j in rej]
    kept = [j for j in range(len(fds)) if j not in rej]
    if not kept:  # the final model is the geometry
        out = Final([], [], [], {}, Jf, r, before_cv)
    else:
        new = {int(c): m for m, c in enumerate(np.setdiff1d(np.arange(fin.A.shape[1]), drop))}
        col_of = {fin.accepted[j]: [new[c] for c in fin.col_of[fin.accepted[j]]] for j in kept}
        out = replace(fin, findings=[fds[j] for j in kept], accepted=[fin.accepted[j] for j in kept],
                      contributions=[fin.contributions[j] for j in kept], col_of=col_of, A=A_k, r_final=r_k,
                      after_cv=cv_k)
    return out, rejected, worse, all_cv


def carried(fin: Final, k: int, alpha: float) -> dict[str, list[int]]:
    """{finding label: measurement rows} for findings the rest of the records do not corroborate: not significant
    at `checks.CORROBORATION_ALPHA` (or the family α, if larger) without their ≤ 2 most influential records."""
    out = {}
    nk = fin.r_final.size
    for fd, i, c in zip(fin.findings, fin.accepted, fin.contributions):
        rest = np.setdiff1d(np.arange(fin.A.shape[1]), fin.col_of[i])
        rows = checks.carried_by(fin.r_final - c.reshape(nk), fin.A[:, rest], fin.A[:, fin.col_of[i]],
                                 max(alpha, checks.CORROBORATION_ALPHA))
        if rows is not None:
            out[f"{fd['effect']}@{fd['location']}"] = sorted({int(q) // k for q in rows})
    return out


def misspecification(findings: list, effects: list, r_final: np.ndarray, A: np.ndarray, variables: list,
                     alpha: float) -> list[str]:
    """Mark findings whose own variable still shows structure `low`; returns those variables."""
    misfit = []
    for fd, e in zip(findings, effects):
        bad = checks.misspecified(r_final, A, checks.related(e.variable, str(e.location), variables), alpha)
        if bad is not None:
            fd["evidence"]["p_value_own_variable_structure"] = bad[0]
            misfit.append(bad[1])
            fd["confidence"] = "low"
            fd["note"] = (f"a flexible function of {bad[1]} still adds to it (p = {bad[0]:.2g}): "
                          f"its functional form does not capture what acts along that variable")
    return misfit


def twins(findings: list, gates: list) -> None:
    """List the library candidates the gate found indistinguishable from each finding; a `high`
    finding with such a twin becomes `medium` (its name is not unique in this campaign)."""
    for fd in findings:
        tw = [g.effect for g in gates if not g.identifiable
              and g.reason == f"indistinguishable from {fd['effect']}@{fd['location']} in this campaign"]
        if not tw:
            continue
        fd["indistinguishable_from"] = [{"effect": e.name, "location": str(e.location), "advice": e.advice}
                                        for e in tw]
        if fd["confidence"] == "high":
            fd["confidence"] = "medium"
            fd["note"] = (f"this campaign cannot tell it from {', '.join(e.label for e in tw)} "
                          f"(> 95 % of the signature shared): {tw[0].advice}")


def look_alike_cap(findings: list) -> None:
    """A `high` finding with look-alikes (names the campaign can hardly tell from it, or candidates the gate set
    aside that would explain it as well: `untested_look_alikes`) becomes `medium`; the other forms of its own
    family at its own place (`inference.forms`: chosen by held-out error) do not count."""
    for fd in findings:
        base = fd["location"].split(" (")[0]  # forms of one family at one place are alike by construction
        al = [a for a in (fd.get("look_alikes") or []) + (fd.get("untested_look_alikes") or [])
              if not (a["effect"] == fd["effect"] and a["location"].split(" (")[0] == base)]
        if fd["confidence"] == "high" and al:
            names = ", ".join(f"{a['effect']}@{a['location']} (" + (f"Δχ² {a['delta_chi2']:.2g})" if "delta_chi2" in a
                                                                    else "not testable here)") for a in al)
            fd["confidence"] = "medium"
            fd["note"] = (f"the campaign can hardly tell it from {names}: the swap fits almost as well; "
                          f"{al[0].get('advice') or 'vary what separates them'}")
