"""Gross misfit screen: do the measurements fit the robot at all?  (functional core)

Residuals orders of magnitude above the instrument's declared σ after a short fit are not a
calibration result but wrong input: lengths in the wrong unit, angles in degrees read as
radians, swapped position columns, or the wrong chain (root/tip, robot).  The screen fits the
model with a small evaluation budget (seconds, never the open-ended solve a hopeless problem
makes), and when the RMS exceeds GROSS_FACTOR × σ it refits each likely mistake undone — joint
angles ×π/180 or ×180/π, each pair of position columns swapped — and names the one that brings
the residuals near the instrument, or says none does (then the chain or the robot description is
the likely cause).  Length units it judges before any fit: the measured points' spread against the
robot's (`spread_ratio`).

σ: the campaign's ``sigma_m`` (`robocal import csv --sigma-m`) or ``tracker_sigma_m``; without a
declared one, DEFAULT_SIGMA_M (a loose ceiling: no calibration instrument leaves 30 mm after a fit).
A model whose residuals are not lengths states its unit (``residual_unit``: a camera's px); its σ is
the campaign's ``sigma_px``, else DEFAULT_SIGMA_PX (30 px after a fit is no lens, but a wrong pose
convention or target).

The short fits use a subsample of whole natural groups (`pipeline.identify.natural_groups`: a
camera's images, a coincidence's sockets, one posture's tips), spread evenly over the table.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

GROSS_FACTOR = 30.0
EXPLAINED_FACTOR = 5.0  # a mistake undone explains the misfit when the RMS falls within this × σ
DEFAULT_SIGMA_M = 1e-3
SCREEN_NFEV = 40  # function evaluations per solve of the short fit
SCREEN_ROWS = 40  # measurements the short fits use at least (whole groups, evenly spaced)
SCREEN_GROUPS = 5  # and at least this many whole groups (a camera's start needs several views)
DEFAULT_SIGMA_PX = 1.0
UNIT_BAND = (300.0, 3000.0)  # measured / predicted spread of the points in this band (or its inverse): mm vs m
LENGTH_COLUMNS = ("position", "point", "coordinate")


def declared_sigma(campaign: dict, unit: str = "m") -> float | None:
    """The instrument's 1σ (in `unit`: m, or px for a camera) the campaign declares, or None."""
    for k in (("sigma_m", "tracker_sigma_m", "instrument_sigma_m") if unit == "m" else (f"sigma_{unit}",)):
        v = (campaign or {}).get(k)
        if isinstance(v, (int, float)) and np.isfinite(v) and v > 0:
            return float(v)
    return None


def quick_rms(model, table: dict, options=None) -> float:
    """Robust RMS residual (m) after a short fit (SCREEN_NFEV evaluations per solve, the rank re-tested as identify
    does, negative compliances not refused: an RMS, not parameter values, and each refusal round is another
    solve): the median absolute residual / 0.6745 (the RMS of Gaussian residuals), so that a few gross records
    — which the outlier checks name — do not make good data look like a unit mistake; rows the model cannot
    evaluate at the start (an unreachable configuration) are left to those checks.  NaN if the fit itself
    cannot be evaluated (a singular configuration among the rows): the screen then does not judge."""
    from pipeline.identify.least_squares import FitOptions, fit
    from pipeline.identify.model import n_rows, take

    opts = replace(options or FitOptions(), max_nfev=SCREEN_NFEV, before=False, physical=False)
    try:
        with np.errstate(all="ignore"):
            r0 = np.asarray(model.residuals(model.initial_guess(table) if hasattr(model, "initial_guess")
                                            else model.nominal(), table), float).reshape(n_rows(table), -1)
            finite = np.all(np.isfinite(r0), axis=1)
            if finite.sum() < max(3, finite.size // 2):
                return float("inf")
            f = fit(model, table if finite.all() else take(table, finite), opts)
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        return float("nan")
    r = np.abs(np.asarray(f.residuals_after, float))
    r = float(np.median(r) / 0.6745) if r.size and np.all(np.isfinite(r)) else float("inf")
    return r if np.isfinite(r) else float("inf")


def _variants(table: dict) -> list[tuple[str, dict]]:
    """The likely mistakes undone: (description, corrected table).  Length units are judged by
    `spread_ratio` instead: scaling the data scales its residuals, so a refit cannot tell."""
    out = []
    lengths = [c for c in LENGTH_COLUMNS if c in table and np.asarray(table[c]).dtype.kind == "f"]
    if "joint_positions" in table:
        q = np.asarray(table["joint_positions"], float)
        out.append(("joint angles are in degrees but were read as radians", {**table, "joint_positions": np.radians(q)}))
        out.append(("joint angles are in radians but were read as degrees", {**table, "joint_positions": np.degrees(q)}))
    for c in lengths:  # any two columns swapped (or one sign flipped) is a mirror image: one refit tells them all,
        v = np.asarray(table[c], float)  # since the registration's rotation turns one mirror into another
        if v.ndim == 2 and v.shape[1] == 3:
            out.append((f"the {c} columns are mirrored: two of x, y, z swapped (or one sign flipped)",
                        {**table, c: v[:, [1, 0, 2]]}))
    return out


def spread_ratio(model, table: dict) -> float | None:
    """Spread (RMS distance from the centroid) of the measured positions over that of the nominal
    model's points at the same joints: a registration moves and turns, it does not scale, so a ratio
    near 1000 or 1/1000 is a length unit.  None without a 3-D position column."""
    c = next((c for c in ("position", "point") if c in table and np.ndim(table[c]) == 2), None)
    if c is None:
        return None
    meas = np.asarray(table[c], float)
    try:
        pred, _ = model.points(model.nominal(), table)
    except Exception:  # noqa: BLE001 — a model whose points need more than the table has: no ratio
        return None
    sp = lambda p: float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1))))  # noqa: E731
    a, b = sp(meas), sp(np.asarray(pred, float))
    return a / b if b > 0 else None


def _subset(model, table: dict) -> dict:
    """Whole natural groups spread evenly: at least SCREEN_ROWS rows and SCREEN_GROUPS groups.  Known-distance
    rows between sockets (``group_b``) stay only where both sockets do."""
    from pipeline.identify.model import n_rows, take
    from pipeline.identify.natural_groups import natural_groups, whole_groups

    n = n_rows(table)
    if n <= SCREEN_ROWS:
        return dict(table)
    keep = np.zeros(n, bool)
    keep[whole_groups(natural_groups(model, table), SCREEN_ROWS, SCREEN_GROUPS)] = True
    if "group_b" in table and "kind" in table:
        dist = np.asarray(table["kind"]) == 1
        touched = np.asarray(table["group"])[keep & ~dist]
        keep &= ~dist | np.isin(np.asarray(table["group_b"]), touched)
    return take(table, keep)


def _fmt(v: float, unit: str, digits: int = 3) -> str:
    """A residual figure for display: mm for lengths (m), else as is (px)."""
    return f"{v * 1e3:.{digits}g} mm" if unit == "m" else f"{v:.{digits}g} {unit}"


def screen(model, table: dict, campaign: dict | None, options=None) -> dict:
    """{status pass|fail, rms_m, sigma_m, declared, cause, message}: the screen of the module docstring."""
    unit = getattr(model, "residual_unit", "m")
    sigma = declared_sigma(campaign or {}, unit)
    ref = sigma if sigma is not None else (DEFAULT_SIGMA_M if unit == "m" else DEFAULT_SIGMA_PX)
    ratio = spread_ratio(model, table)
    lo, hi = UNIT_BAND
    if ratio is not None and (lo < ratio < hi or 1 / hi < ratio < 1 / lo):
        unit = "lengths are in mm but were read as m" if ratio > 1 else "lengths are in m but were read as mm"
        return {"status": "fail", "rms_m": None, "sigma_m": ref, "declared": sigma is not None, "cause": unit,
                "message": f"the measured points spread {ratio:.3g}× as far as the robot's points at the same joints "
                           f"(a registration does not scale): likely cause: {unit}"}
    table = _subset(model, table)
    rms = quick_rms(model, table, options)
    out = {"rms_m": rms, "sigma_m": ref, "declared": sigma is not None, "cause": None}
    if unit != "m":
        out["residual_unit"] = unit
    if np.isnan(rms):  # the short fit could not be evaluated: the other checks name the rows
        return out | {"rms_m": None, "status": "pass",
                      "message": "not judged: the short fit could not be evaluated (a singular configuration)"}
    if rms <= GROSS_FACTOR * ref:
        out |= {"status": "pass", "message": f"robust residual RMS after a short fit {_fmt(rms, unit)}, within "
                                             f"{GROSS_FACTOR:g}× the instrument's σ {_fmt(ref, unit)}"}
        return out
    tried = []
    for what, t in _variants(table):  # stop at the first that explains the misfit
        v = quick_rms(model, t, options)
        tried.append((what, float("inf") if np.isnan(v) else v))
        if tried[-1][1] <= min(EXPLAINED_FACTOR * ref, rms / 10):
            break
    best = min(tried, key=lambda t: t[1]) if tried else None
    what = ("declared" if sigma is not None else f"assumed (none declared{'; --sigma-m' if unit == 'm' else ''})")
    head = (f"robust residual RMS after the fit {_fmt(rms, unit, 4)} is {rms / ref:.3g}× the instrument's {what} σ "
            f"{_fmt(ref, unit)}: the measurements do not fit the robot")
    if best is not None and best[1] < rms / 10 and best[1] <= EXPLAINED_FACTOR * ref:
        out["cause"] = best[0]
        out["message"] = f"{head}; likely cause: {best[0]} (undone, the RMS is {_fmt(best[1], unit)})"
    else:
        out["cause"] = "chain"
        out["message"] = (f"{head}; no unit or column mix-up explains it (best: "
                          f"{best[0] if best else 'none'}, {_fmt(best[1] if best else float('nan'), unit)}): likely "
                          f"the wrong chain (root/tip), the wrong robot description, or an understated σ")
    out["status"] = "fail"
    return out
