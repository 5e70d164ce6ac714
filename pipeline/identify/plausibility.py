"""Physical plausibility of an estimate: robot parameters further from nominal than their prior allows.

A fitted joint origin 15 mm from its URDF value when the prior says 2 mm (1σ) is either a wrong robot
description or the fit absorbing something else (a wrong joint mapping, a moved instrument).  Either
way the user must hear of it: each such parameter is named (results ``implausible``, a warning) and
the status is never ``pass`` over it.  The registration group (instrument frame, tool, targets,
socket points, planes) is not judged: an instrument stands anywhere.  Gravity-compliance terms a
shrinkage fit estimated with the registration (`pipeline.identify.physics_choice`) are judged by their
sign instead of the rigid robot's prior: a negative compliance has no physical stiffness.
"""

from __future__ import annotations

import numpy as np

PLAUSIBLE = 3.0  # prior σ beyond which an estimate is named


def implausible(model, x: np.ndarray, free: np.ndarray, prior_sigma: np.ndarray, by_sign=()) -> list[dict]:
    """[{name, estimate, nominal, prior_sigma, z}] of the estimated robot parameters beyond `PLAUSIBLE` σ;
    `by_sign`: compliance names judged only by their sign (named when negative)."""
    groups = model.groups() if hasattr(model, "groups") else {}
    if not groups:
        return []
    reg = set(groups.get("registration", []))
    names, nominal = model.parameter_names(), np.asarray(model.nominal(), float)
    out = []
    for i, n in enumerate(names):
        s = float(prior_sigma[i])
        if not free[i] or n in reg or not s > 0 or (n in by_sign and float(x[i]) >= 0):
            continue
        z = (float(x[i]) - nominal[i]) / s
        if abs(z) > PLAUSIBLE:
            out.append({"name": n, "estimate": float(x[i]), "nominal": float(nominal[i]), "prior_sigma": s, "z": z})
    return out


def warnings_of(items: list[dict]) -> list[str]:
    """One warning per implausible parameter."""
    return [f"{p['name']}: estimated {p['z']:+.1f} prior σ from nominal ({p['estimate']:.6g} against {p['nominal']:.6g}, "
            f"prior σ {p['prior_sigma']:.3g}): physically implausible" for p in items]
