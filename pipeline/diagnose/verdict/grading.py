"""Step 6 of the diagnosis: where the rest is, and how far each name can be trusted.

- `locate`: lack of fit of the final residuals against smooth functions of the adapter's
  variables (independent errors: grouped F; pose clusters: the wild cluster bootstrap or the
  adapter's physical cluster-error model) → `unexplained_where` entries with advice;
- `grade`: a finding is `low` when it is re-selected in few bootstrap resamples, has no
  held-out improvement, leaves structure along its own variable, is misspecified there
  (`arbiter.misspecification`), or is a likely proxy of located structure or of a narrow bump
  along its own variable; `medium` with a twin the campaign cannot tell from it (`arbiter.twins`) or a
  look-alike the data can hardly tell from it (`arbiter.look_alike_cap`);
- `floor_and_status`: back to the declared noise floor (`checks.floor_check`), the status, and
  `high` findings of a partial diagnosis downgraded to `medium`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.diagnose.inference import resampling
from pipeline.diagnose.inference.projection import orthonormal, project_out
from pipeline.diagnose.verdict import arbiter, checks, lack_of_fit
from pipeline.diagnose.verdict.physical_lack_of_fit import (
    _extremeness,
    physical_lack_of_fit,
)

MIN_BOOTSTRAP = 0.5  # a confident finding is re-selected in at least this share of resamples


def locate(ad, xg: np.ndarray, r_final: np.ndarray, A: np.ndarray, W, nk: int, alpha: float, seed: int,
           src: list | None, nm, cl: np.ndarray | None, M) -> tuple[list, list, list[dict]]:
    """(variables, lack-of-fit tests, `unexplained_where` entries sorted most extreme first)."""
    variables = ad.variables(xg)
    if W is None:
        lof = lack_of_fit.test(r_final, A, variables, nk - A.shape[1], alpha)
    else:
        if ad.cluster_model is not None and nm is not None:  # parametric reference (physical cluster error)
            lof = physical_lack_of_fit(ad, xg, r_final, A, variables, src, nm, cl, M, W, alpha, seed)
        else:
            vw = [dataclasses.replace(v, columns=W(v.columns)) for v in variables]
            lof = lack_of_fit.test(W(r_final), W(A), vw, W.n_effective - A.shape[1], alpha, whiten=W,
                                   original=(r_final, A, variables), cluster=cl, seed=seed)
    where = [{"variable": t.variable, "p_value": t.p_holm, "statistic": t.statistic,
              "region": list(t.region) if isinstance(t.region, tuple) else t.region, "peak_m": t.peak_m,
              "advice": (ad.advice and ad.advice(t.variable)) or checks.advice_for(t.variable)}
             for t in sorted(lof, key=_extremeness)
             if t.significant]
    return variables, lof, where


def grade(findings: list[dict], effects: list, contributions: list, col_of_list: list, A: np.ndarray,
          r_final: np.ndarray, variables: list, where: list[dict], gates: list, W, alpha: float) -> list[str]:
    """Set each finding's `confidence` / `note` (module docstring); returns the misspecified variables.
    `effects` and `col_of_list` are the findings' library entries and design columns, in order."""
    nk = r_final.size
    flagged = {w["variable"] for w in where}
    for fd, e in zip(findings, effects):
        ev = fd["evidence"]
        if ev["bootstrap_frequency"] < MIN_BOOTSTRAP or ev["cv_rms_after_m"] >= ev["cv_rms_before_m"]:
            fd["confidence"] = "low"
            fd["note"] = "selected in few bootstrap resamples or no held-out improvement"
        if e.variable in flagged:
            fd["confidence"] = "low"
            fd["note"] = (f"structure remains in {e.variable} that {e.name} does not explain; "
                          "the effect may be something outside the library")
    # misspecification along each finding's own variable, and names the campaign cannot make unique
    misfit = arbiter.misspecification(findings, effects, r_final, A, variables, alpha) if W is None else []
    arbiter.twins(findings, gates)
    arbiter.look_alike_cap(findings)
    # a likely proxy: a finding that is no longer significant once the located unexplained structure, or
    # a narrow bump along the finding's own variable (a localised error there), is in the design, while
    # that structure stays significant beside the finding (a real effect explains the bump away instead)
    by_name = {v.name: v for v in variables}
    B_where = [lack_of_fit.located_columns(by_name[w["variable"]], w["region"])
               for w in where if isinstance(w["region"], list)]
    for fd, e, c, cols in zip(findings, effects, contributions, col_of_list):
        if fd["confidence"] != "high":
            continue
        keep_cols = np.setdiff1d(np.arange(A.shape[1]), cols)
        r_wo = r_final - c.reshape(nk)
        B, why, mult = list(B_where), [w["variable"] for w in where], 1
        _local_alternative(fd, e, variables, r_wo, A[:, keep_cols], A[:, cols], W, alpha)
        if fd["confidence"] != "high":
            continue
        own = by_name.get(e.variable)
        reg = None if own is None else lack_of_fit.best_bump(own, r_wo, A[:, keep_cols], W)
        if reg is not None:
            B.append(lack_of_fit.located_columns(own, reg))
            why.append(f"a localised bump in {own.name} at [{reg[0]:.4g}, {reg[1]:.4g}] {own.unit}")
            mult = 2 * lack_of_fit.N_SCAN  # the bump is the best of the narrow scan: Bonferroni over it
        if not B:
            continue
        p_f, p_b = lack_of_fit.partial_p(r_wo, A[:, keep_cols], A[:, cols], np.hstack(B), W)
        fd["evidence"]["p_value_given_alternatives"] = p_f
        if p_f > alpha and min(1.0, p_b * mult) <= alpha:
            fd["confidence"] = "low"
            fd["note"] = (f"not significant (p = {p_f:.2g}) once {' and '.join(why)} is modelled, which stays "
                          f"significant beside it: likely a proxy for something outside the library")
    return misfit


def beyond_plausible(fd: dict, e) -> str | None:
    """The note of a finding whose fitted size lies beyond the physically plausible size its library term
    declares (`Effect.plausible`) by more than 2σ, else None: the name then stands for something else the
    library does not hold (a proxy).  For a library whose parameters are physical sizes (the dynamics'
    friction and drive terms); a geometric library's plausible bound is the gate's, and some of its forms
    (a warm-up's amplitude) are not sizes of that kind.  Its size is the norm of the parameters in the term's first unit
    (an eccentricity's two phases together; a Stribeck term's level, not its speed), σ their largest."""
    ps = [p for p in fd.get("parameters", []) if p["unit"] == e.units[0]]
    if not ps or not np.isfinite(e.plausible):
        return None
    size = float(np.linalg.norm([p["value"] for p in ps]))
    sd = max(p["std"] for p in ps)
    if not size - 2 * sd > e.plausible:
        return None
    return (f"its fitted size {size:.3g} ± {sd:.2g} {e.units[0]} is beyond the {e.plausible:.3g} {e.units[0]} the "
            f"library holds plausible for {e.name}: likely a proxy for something outside the library")


def _local_alternative(fd: dict, e, variables: list, r_wo: np.ndarray, A_rest: np.ndarray, S: np.ndarray, W,
                       alpha: float) -> None:
    """A `high` finding acting over a whole place (a face's flatness) is kept `high` only if the data favour it
    over the best local error there (the narrow bump at one of the place's contacts, `Variable.local`, that
    explains most of the residual without the finding): the finding significant beside it.  Otherwise `medium`
    (a local error fits as well), or `low` when the local one also stays significant beside the finding
    (Bonferroni over the bumps tried): likely a dent, outside the library."""
    lv = next((v for v in variables if v.local is not None and v.place and v.place == str(e.location)), None)
    if lv is None:
        return
    L = lv.local if W is None else W(lv.local)
    y, Ar = (r_wo, A_rest) if W is None else (W(r_wo[:, None])[:, 0], W(A_rest))
    QA = orthonormal(Ar)
    P = project_out(L, QA)
    nrm = np.linalg.norm(P, axis=0)
    ok = nrm > 1e-6 * np.maximum(np.linalg.norm(L, axis=0), 1e-300)
    if not ok.any():
        return
    yp = project_out(y[:, None], QA)[:, 0]
    gain = np.where(ok, (P.T @ yp) ** 2 / np.maximum(nrm, 1e-300) ** 2, -np.inf)
    best = int(np.argmax(gain))
    p_f, p_b = lack_of_fit.partial_p(r_wo, A_rest, S, lv.local[:, [best]], W)
    fd["evidence"]["p_value_given_local_alternative"] = p_f
    if p_f <= alpha:
        return
    if min(1.0, p_b * int(ok.sum())) <= alpha:
        fd["confidence"] = "low"
        fd["note"] = (f"not significant (p = {p_f:.2g}) beside a local error on {e.location}, which stays significant "
                      "beside it: likely a local defect (a dent), outside the library")
    else:
        fd["confidence"] = "medium"
        fd["note"] = (f"a local error on {e.location} fits as well (this term p = {p_f:.2g} beside it): the data do "
                      "not favour the whole-face form over a local one")


def floor_and_status(ad, xg: np.ndarray, r_final: np.ndarray, A: np.ndarray, after_cv: np.ndarray, folds: list,
                     findings: list[dict], where: list[dict], worse: bool, misfit: list[str],
                     alpha: float, design: dict | None = None) -> tuple[dict | None, str, str]:
    """(noise-floor check or None, status, reason); downgrades `high` findings of a partial diagnosis.
    `design`: `resampling.holdout_over_insample` (flagged: never `clean`/`explained`)."""
    nk = r_final.size
    floor = None
    if ad.floor_variance is not None:
        vf = ad.floor_variance(xg)
        # decided on the residuals (χ², exact null); the held-out residuals against what the floor gives
        # out of sample are reported beside it (their test, at α/2 beside the χ² at α/2, found 10 % more of
        # the nonlinear warm-ups on 16 seeds but read one clean campaign of 40 above the floor)
        floor = checks.floor_check(r_final, nk - A.shape[1], vf, alpha)
        floor.update(checks.holdout_floor_check(A, after_cv, folds, vf, alpha))
        floor["holdout_rms_over_floor"] = resampling.rms(after_cv) / floor["holdout_rms_expected_at_floor_m"]
    st_name, st_reason = checks.status(len(findings), bool(where), floor, worse, misfit, design)
    if st_name == "partially_explained":
        for fd in findings:
            if fd["confidence"] == "high":
                fd["confidence"] = "medium"
                fd["note"] = f"named, but the diagnosis is only partial: {st_reason.split('; left: ')[-1]}"
    return floor, st_name, st_reason
