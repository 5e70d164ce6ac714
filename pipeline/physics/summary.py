"""What the physics of a calibrated model amounts to: geometry-only against with-physics held-out
error, and each kept term with its value, 1σ and physical reading.

The geometry-only held-out error refits the same model with every physics parameter held at 0
(rigid) under the same k-fold split, so the two figures differ only by the physics terms.  A
term's reading: a joint-compliance c (rad/(N·m)) is a joint stiffness k = 1/c (N·m/rad), its
relative σ that of c (first order); a lateral term is the tilt stiffness of the joint's child frame
about the normal e1 or e2 (`pipeline.physics.gravity.normals`).  A reading-error term
(`pipeline.physics.encoder`) is its value and σ in its unit (rad or rad/rad).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

SUFFIXES = (".compliance", ".lateral1", ".lateral2", ".compliance_load")


def physics_names(model) -> list[str]:
    """The model's physics parameter names (empty for a rigid model)."""
    from pipeline.physics.encoder import SUFFIXES as READING

    extra = getattr(model, "extra_names", None)
    return [n for n in (extra() if extra else []) if n.endswith(SUFFIXES + READING)]


def pretty(v: float) -> str:
    """3.0·10⁴ style (two significant figures, superscript exponent)."""
    if not np.isfinite(v) or v == 0:
        return f"{v:g}"
    e = int(np.floor(np.log10(abs(v))))
    m = v / 10.0**e
    if round(abs(m), 1) >= 10:
        m, e = m / 10, e + 1
    sup = str(e).translate(str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹"))
    return f"{m:.1f}·10{sup}"


def term(name: str, c: float, std: float | None, tree=None) -> dict:
    """One physics term's figures and reading (module docstring); `tree` names a coupling's driver."""
    from pipeline.physics.encoder import describe, is_encoder

    if is_encoder(name):
        return describe(tree, name, c, std)
    joint, kind = name.rsplit(".", 1)
    if kind == "compliance_load":  # the compliance's change per N·m of load: a stiffness that depends on it
        return {"joint": joint, "family": "load-compliance", "axis": "joint axis", "parameter": name,
                "term": "compliance_load", "value": c, "std": std, "unit": "rad/(N·m)²",
                "compliance_per_load_rad_per_Nm2": c, "compliance_per_load_std_rad_per_Nm2": std,
                "reading": f"{joint}: compliance {'falls' if c < 0 else 'grows'} by {abs(c):.3g} rad/(N·m) per N·m "
                           f"of load ({'stiffens' if c < 0 else 'softens'} under load)"}
    family = "joint-compliance" if kind == "compliance" else "lateral-compliance"
    axis = {"compliance": "joint axis", "lateral1": "normal e1", "lateral2": "normal e2"}[kind]
    rel = abs(std / c) if std is not None and c != 0 else None
    k = 1.0 / c if c > 0 else None
    out = {"joint": joint, "family": family, "axis": axis, "parameter": name, "compliance_rad_per_Nm": c,
           "compliance_std_rad_per_Nm": std, "stiffness_Nm_per_rad": k, "relative_std": rel,
           "stiffness_std_Nm_per_rad": (std / c**2) if k is not None and std is not None else None}
    what = "stiffness" if kind == "compliance" else f"tilt stiffness about {axis}"
    if k is not None:
        out["reading"] = f"{joint}: {what} {pretty(k)} N·m/rad" + (f" ± {100 * rel:.0f} %" if rel is not None else "")
    else:
        out["reading"] = (f"{joint}: compliance about the {axis} {c:.3g} rad/(N·m) ≤ 0 — no physical stiffness "
                          "(the term absorbs something else)")
    return out


def summarise(model, fit, data, options, folds: int, seed: int, holdout_m: float) -> dict | None:
    """The `physics` section of identify's fit.json (None for a rigid model).  `fit`: the final
    `least_squares` fit (x, std, free, names); `options`: its `FitOptions`; `holdout_m`: its held-out RMS."""
    from pipeline.identify.least_squares import cross_validate
    from pipeline.physics.compliance import EQUILIBRIUM
    from pipeline.physics.encoder import BACKLASH_ABSENT

    phys = physics_names(model)
    if not phys:
        return None
    names = list(fit.names)
    idx = [names.index(n) for n in phys]
    free = np.asarray(fit.free, bool)
    kept = [i for i in idx if free[i]]
    if kept:
        opts = replace(options, fixed=tuple(sorted(set(options.fixed) | set(phys))))
        r = cross_validate(model, data, k=folds, seed=seed, options=opts)
        geometry = float(np.sqrt(np.nanmean(r**2)))
    else:
        geometry = float(holdout_m)
    std = np.full(len(names), np.nan)
    if fit.std is not None:
        s = np.asarray(fit.std, float)
        std[: s.size] = s if s.size == len(names) else np.nan
    tree = getattr(model, "kin", None)
    terms = [term(names[i], float(fit.x[i]), float(std[i]) if np.isfinite(std[i]) else None, tree) for i in kept]
    label = {"compliance": "joint", "compliance_load": "load-dependent", "lateral1": "lateral", "lateral2": "lateral", "ecc_sin": "eccentricity",
             "ecc_cos": "eccentricity", "scale": "scale", "coupling": "coupling", "backlash": "backlash"}
    offered = sorted({f"{n.rsplit('.', 1)[0]} ({label[n.rsplit('.', 1)[1]]})" for n in phys})
    gain = 1.0 - float(holdout_m) / geometry if geometry > 0 else 0.0
    return {"holdout_geometry_only_m": geometry, "holdout_with_physics_m": float(holdout_m),
            "holdout_gain": gain, "kept": bool(kept), "terms": terms, "offered": offered,
            "payload": [{"mass_kg": m, "link": ln, "com_m": list(c)} for m, ln, c in getattr(model, "payload", ())],
            "equilibrium": EQUILIBRIUM,
            "not_fitted": [{"family": f, "reason": BACKLASH_ABSENT} for f in getattr(model, "absent", ())]}


def lines(doc: dict) -> list[str]:
    """The story in words, mm: geometry-only vs with-physics held-out, then each kept term."""
    g, w = doc["holdout_geometry_only_m"] * 1e3, doc["holdout_with_physics_m"] * 1e3
    if not doc["kept"]:
        out = [f"physics: no term kept (held-out {w:.3f} mm with geometry only; offered: "
               f"{', '.join(doc['offered']) or 'none'})"]
    else:
        out = [f"physics: held-out {g:.3f} mm geometry only → {w:.3f} mm with {len(doc['terms'])} physics term(s)"]
    return out + [f"  {t['reading']}" for t in doc["terms"]] + [f"  {n['reason']}" for n in doc.get("not_fitted", [])]
