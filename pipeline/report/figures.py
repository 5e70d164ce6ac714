"""The report's figures as pure functions of the run artefacts (SI in, SI out; display units only
in the `display_*` helpers).  `results_figures` is what the report stage adds to results.json."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.report import labels
from pipeline.report.artefacts import RunArtefacts, residual_matrix

DISPLAY = {"m": ("mm", 1e3), "rad": ("deg", 180.0 / np.pi), "m/px": ("µm/px", 1e6)}


def rms(a: np.ndarray) -> float | None:
    """RMS of the finite entries, None if there are none."""
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    return float(np.sqrt(np.mean(a**2))) if a.size else None


def display(value: float | None, unit: str) -> tuple[float | None, str]:
    """(value, unit) in display units: m → mm, rad → deg, others unchanged."""
    u, k = DISPLAY.get(unit, (unit, 1.0))
    return (None if value is None else float(value) * k), u


def summary(art: RunArtefacts) -> dict[str, Any]:
    """Headline figures (SI)."""
    res = art.residuals
    before, after, hold = (residual_matrix(res, k) for k in ("before", "after", "holdout"))
    fit = art.fit
    free = np.asarray(fit.get("free", []), bool)
    u = art.used
    out: dict[str, Any] = {
        "system": art.system,
        "n_measurements": int(len(res["record"])),
        "n_used": int(u.sum()),
        "residual_dim": int(after.shape[1]),
        "rms_before_m": rms(before[u]),
        "rms_after_m": rms(after[u]),
        "holdout_rms_m": rms(hold[u]),
        "max_abs_after_m": float(np.nanmax(np.abs(after[u]))) if after[u].size else None,
        "sigma_m": fit.get("sigma_m"),
        "n_parameters": int(len(fit.get("names", []))),
        "n_identifiable": int(free.sum()),
        "n_rejected": int(max(len(fit.get("rejected_records", []) or []), int((~u).sum()))),
        "loss": fit.get("loss", "linear"),
        "solver_evaluations": len(art.history),
    }
    for k in ("rms_3d_before_m", "rms_3d_after_m", "holdout_rms_3d_m"):  # URDF points / poses (identify)
        if fit.get(k) is not None:
            out[k] = fit[k]
    obs = art.observe or {}
    sig = obs.get("predicted_point_sigma_m")
    if sig:
        out["predicted_point_sigma_rms_m"] = rms(np.asarray(sig, float))
        out["predicted_point_sigma_max_m"] = float(np.max(sig))
    for k in ("O1", "O2", "O3", "O4", "O5"):
        if k in obs:
            out[k] = obs[k]
    return out


def parameter_rows(fit: dict) -> list[dict[str, Any]]:
    """One row per parameter in display units: name, unit, nominal, estimate, change, std, free, reason, and
    std_independent (the independent-row σ the stated std replaced, `fit.json` ``std_independent``) or None."""
    names = fit["names"]
    units = fit.get("units", ["m"] * len(names))
    nom = np.asarray(fit["nominal"], float)
    x = np.asarray(fit["x"], float)
    std = np.asarray(fit.get("std", np.zeros(len(names))), float)
    free = np.asarray(fit.get("free", np.ones(len(names), bool)), bool)
    iid = np.asarray(fit["std_independent"], float) if fit.get("std_independent") is not None else None
    reasons = fit.get("reasons", {}) or {}
    rows = []
    for i, n in enumerate(names):
        _, u = display(0.0, units[i])
        k = DISPLAY.get(units[i], (units[i], 1.0))[1]
        reason = reasons.get(n, reasons.get(str(i), "")) if isinstance(reasons, dict) else ""
        rows.append({"name": n, "unit": u, "nominal": nom[i] * k, "estimate": x[i] * k,
                     "change": (x[i] - nom[i]) * k, "std": std[i] * k if free[i] else None,
                     "free": bool(free[i]), "reason": "" if free[i] else str(reason),
                     "std_independent": iid[i] * k if iid is not None and free[i] else None})
    return rows


def group_table(art: RunArtefacts) -> list[dict[str, Any]]:
    """Per face/channel/leg: count and RMS before, after and held out (m)."""
    res = art.residuals
    groups = np.asarray(res.get("group", np.full(len(res["record"]), "all"))).astype(str)
    mats = {k: residual_matrix(res, k) for k in ("before", "after", "holdout")}
    rows = []
    for g in sorted(set(groups)):
        m = (groups == g) & art.used
        rows.append({"group": g, "n": int(m.sum()),
                     **{f"rms_{k}_m": rms(v[m]) if v.shape[1] else None for k, v in mats.items()}})
    return rows


@dataclass(frozen=True)
class ResidualSeries:
    """Residuals per measurement, flattened over components (one point per component)."""

    group: np.ndarray  # (n·k,) str
    t_s: np.ndarray  # (n·k,) s since the first measurement
    before: np.ndarray  # (n·k,) m
    after: np.ndarray
    holdout: np.ndarray
    joints: dict[str, np.ndarray]  # joint name -> (n·k,) rad
    component: np.ndarray  # (n·k,) int
    used: np.ndarray  # (n·k,) bool: False for measurements rejected as outliers
    prismatic: frozenset = frozenset()  # joints whose readings are m (plotted in mm, not deg)
    time_label: str = "time since first measurement (s)"  # or the table row, for tables without times
    group_title: str = "face / channel"  # what a residual group is (a jig face; a URDF campaign's target)
    scale: float = 1e3  # display factor of the residuals: m → mm; 1 for a camera's px
    unit: str = "mm"  # their display unit


def residual_series(art: RunArtefacts) -> ResidualSeries:
    """Join residuals with the measurement table (by record) for plots against time and joints."""
    res = art.residuals
    n = len(res["record"])
    mats = {k: residual_matrix(res, k) for k in ("before", "after", "holdout")}
    k = max(m.shape[1] for m in mats.values()) or 1
    for key, m in mats.items():
        if m.shape[1] != k:
            mats[key] = np.full((n, k), np.nan)
    t_s, time_label = labels.time_axis(np.asarray(res["timestamp_ns"], np.int64))
    joints: dict[str, np.ndarray] = {}
    meas = art.measurements
    if meas is not None and "record" in meas:
        pos = {int(r): i for i, r in enumerate(meas["record"])}
        idx = np.array([pos.get(int(r), -1) for r in res["record"]])
        ok = idx >= 0
        for name, v in art.joint_columns().items():
            col = np.full(n, np.nan)
            col[ok] = v[idx[ok]]
            joints[name] = col
    groups = np.asarray(res.get("group", np.full(n, "all"))).astype(str)
    rep = lambda a: np.repeat(np.asarray(a), k)  # noqa: E731
    return ResidualSeries(group=rep(groups), t_s=rep(t_s), before=mats["before"].ravel(),
                          after=mats["after"].ravel(), holdout=mats["holdout"].ravel(),
                          joints={j: rep(v) for j, v in joints.items()}, component=np.tile(np.arange(k), n),
                          used=rep(art.used), prismatic=art.prismatic_joints(), time_label=time_label,
                          group_title=labels.group_title(art.system),
                          **dict(zip(("scale", "unit"), labels.residual_display((art.fit or {}).get("residual_unit")))))


def correlation(art: RunArtefacts) -> tuple[list[str], np.ndarray] | None:
    """Correlation matrix over the free parameters: observe's, else from fit.json's covariance."""
    fit = art.fit
    free = np.asarray(fit.get("free", []), bool)
    names = list((art.observe or {}).get("correlation_names") or [n for n, f in zip(fit.get("names", []), free) if f])
    c = (art.observe or {}).get("correlation")
    if c is not None:
        c = np.asarray(c, float)
    elif fit.get("cov") is not None:
        cov = np.asarray(fit["cov"], float)
        if cov.size == 0:
            return None
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))
        sd[sd == 0] = 1.0
        c = cov / np.outer(sd, sd)
    else:
        return None
    if c.ndim != 2 or c.shape[0] != c.shape[1]:
        return None
    if len(names) != c.shape[0]:
        names = [f"p{i}" for i in range(c.shape[0])]
    return names, c


def strongest_correlations(names: list[str], c: np.ndarray, k: int = 8) -> list[tuple[str, str, float]]:
    """The k largest |correlations| between distinct parameters."""
    iu = np.triu_indices(c.shape[0], 1)
    vals = c[iu]
    order = np.argsort(-np.abs(vals))[:k]
    return [(names[iu[0][o]], names[iu[1][o]], float(vals[o])) for o in order]


def singular_values(art: RunArtefacts) -> np.ndarray | None:
    s = (art.observe or {}).get("singular_values")
    return None if s is None else np.asarray(s, float)


def provenance(art: RunArtefacts, version: str, params: dict[str, Any]) -> dict[str, Any]:
    """Input file hash, robocal version, every stage's parameters and key."""
    rec = art.recording
    return {
        "input_sha256": art.source.get("sha256"),
        "input_path": art.source.get("path"),
        "robocal_version": version,
        "metadata": {k: _brief(v) for k, v in (rec.get("metadata") or {}).items()},
        "stages": {s: {"params": d.get("params", {}), "key": d.get("key"),
                       "robocal_version": d.get("robocal_version")} for s, d in art.stages.items()},
        "report_params": params,
        "warnings": list(rec.get("warnings", []) or []),
    }


def _brief(v: Any) -> str:
    """A metadata record in one line: its name, else its system, else its scalar fields."""
    if not isinstance(v, dict):
        return str(v)
    if v.get("name"):
        return str(v["name"])
    scalars = {k: x for k, x in v.items() if isinstance(x, (str, int, float, bool))}
    return ", ".join(f"{k}={x}" for k, x in scalars.items())[:300]


def results_figures(art: RunArtefacts) -> dict[str, Any]:
    """Machine-readable figures of the report for results.json (SI)."""
    out = summary(art)
    out["groups"] = group_table(art)
    s = singular_values(art)
    if s is not None and s.size:
        out["condition_number"] = float(s[0] / s[-1]) if s[-1] > 0 else None
    c = correlation(art)
    if c is not None:
        out["max_abs_correlation"] = max((abs(v) for *_, v in strongest_correlations(*c, k=1)), default=None)
    if art.validate:
        checks = art.validate.get("checks", [])
        out["validation"] = {st: sum(1 for ch in checks if ch.get("status") == st) for st in ("pass", "warn", "fail")}
    return out
