"""Whether a fit corrected the robot at all, and when it did not, why: "no correction applied".

A model choice may keep the nominal robot — registration only (the instrument frame, the tool point) and every
robot parameter at its nominal value — because no candidate model predicted data it did not see better.  That is
an honest outcome, but a run that then reports an RMS "after" equal to "before" says nothing of it: the user must
read that no correction was applied, which candidates were tried and why none was kept.  `document` returns that
statement (`results.json` → ``summary.correction``, the command line's summary, the report) from the model choice
that made it: the group selection (`pipeline.identify.complexity`) or the shrinkage choice
(`pipeline.identify.shrinkage_fit`).
"""

from __future__ import annotations

import numpy as np

NONE_APPLIED = "no correction applied"


def robot_parameters(model) -> list[str]:
    """Names of the robot's own parameters: every grouped parameter outside the registration group (instrument
    frame, tool, targets, sockets, planes) and its hidden groups (names starting with ``_``)."""
    groups = model.groups() if hasattr(model, "groups") else {}
    aside = {n for g, v in groups.items() if g == "registration" or g.startswith("_") for n in v}
    return [n for g, v in groups.items() if g != "registration" and not g.startswith("_") for n in v
            if n not in aside]


def applied(model, fit) -> bool:
    """True when the fit moved any robot parameter off its nominal value."""
    names, nominal = list(fit.names), np.asarray(model.nominal(), float)
    idx = [names.index(n) for n in robot_parameters(model) if n in names]
    x = np.asarray(fit.x, float)
    return bool(any(fit.free[i] and x[i] != nominal[i] for i in idx))


def _mm(v: float) -> str:
    return f"{v * 1e3:.4g} mm"


def from_selection(sel) -> tuple[str, list[dict]]:
    """(reason, tried) of a group selection that kept registration only."""
    tried = [{"candidate": r["candidate"], "holdout_rms_m": r["holdout_rms_m"], "against_m": r.get("against_m"),
              "reason": r.get("why", "did not lower the held-out error")} for r in sel.rounds[1:]]
    if not tried:
        return "the model offers no parameter group beyond the registration", tried
    best = min(tried, key=lambda t: t["holdout_rms_m"])
    return (f"no parameter group lowered the held-out error enough to be kept: registration only "
            f"{_mm(sel.holdout_registration_m)}, best candidate {best['candidate']}: {_mm(best['holdout_rms_m'])} "
            f"({best['reason']})"), tried


def from_shrunk(s) -> tuple[str, list[dict]]:
    """(reason, tried) of a shrinkage choice that kept the nominal robot (μ = ∞)."""
    ref = s.gcv.get(np.inf, s.gcv.get(float("inf")))
    tried = [{"candidate": "registration only" if np.isinf(m) else f"μ = {_mm(m)}",
              "holdout_rms_m": float(np.sqrt(v))} for m, v in sorted(s.gcv.items(), reverse=True)]
    passed = [p for p in s.passed_over if p["mu_m"] is not None]
    if passed:
        why = "; ".join(f"μ = {_mm(p['mu_m'])} (registration {p['registration']}) scored {_mm(p['holdout_rms_m'])}"
                        f"{'' if p['solved'] else ' (linearised)'} but {p['reason']}" for p in passed)
        for p in passed:
            tried.append({"candidate": f"μ = {_mm(p['mu_m'])}, registration {p['registration']}",
                          "holdout_rms_m": p["holdout_rms_m"], "reason": p["reason"], "solved": p["solved"]})
        return (f"registration only kept: every candidate that scored better predicts a left-out group worse than "
                f"the nominal robot does — {why}"), tried
    scored = [t for t in tried if t["candidate"] != "registration only"]
    best = min(scored, key=lambda t: t["holdout_rms_m"], default=None)
    if best is None or ref is None:
        return "registration only kept: no other candidate was scored", tried
    return (f"no candidate predicted the left-out groups better than the nominal robot: registration only "
            f"{_mm(float(np.sqrt(ref)))}, best candidate {best['candidate']}: {_mm(best['holdout_rms_m'])}"), tried


def document(model, fit, selection=None, shrunk=None) -> dict | None:
    """{applied: False, statement, reason, tried} when the chosen model is the nominal robot; None when a
    correction was applied (or the model has no robot parameters to correct)."""
    if not robot_parameters(model) or applied(model, fit):
        return None
    if shrunk is not None:
        reason, tried = from_shrunk(shrunk)
        if shrunk.physics and shrunk.physics.get("candidates"):
            bad = {k: v for k, v in shrunk.physics["candidates"].items() if not v.get("admissible", True)}
            if bad:
                reason += "; physics refused: " + "; ".join(
                    f"{k} (negative compliance {', '.join(v.get('negative', []))})" for k, v in bad.items())
    elif selection is not None:
        reason, tried = from_selection(selection)
    else:
        reason, tried = "every robot parameter was held at its nominal value", []
    return {"applied": False, "statement": f"{NONE_APPLIED}: the nominal robot was kept (registration only)",
            "reason": reason, "tried": tried}


def line(doc: dict) -> str:
    """One line for warnings and the terminal."""
    return f"{NONE_APPLIED} — {doc['reason']}"
