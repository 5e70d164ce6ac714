"""The accuracy verdict of a calibration: map, status, reason, advice (functional core).

Status ``insufficient`` (never ``pass``) when
* fewer than MIN_RESIDUALS_PER_PARAMETER residuals per identified parameter;
* a direction of the point no measurement fixes (a touch campaign without an x-facing face);
* the calibrated model is predicted worse than the uncalibrated one somewhere on the map.
With a tolerance, ``fail`` when the 95 % bound exceeds it anywhere on the map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.accuracy import propagate as P

MIN_RESIDUALS_PER_PARAMETER = 3
UNMEASURED_EIG = 1e-6  # relative eigenvalue of the measured-direction matrix below which a direction is unmeasured


@dataclass(frozen=True)
class Inputs:
    """What the verdict needs (SI).  Jacobians at the estimate; Jp_map_nominal at the
    uncalibrated parameters (for the "worse than uncalibrated" test)."""

    names: list[str]
    free: np.ndarray
    cov_free: np.ndarray
    prior_sigma: np.ndarray
    Jm: np.ndarray  # (m, P) measurement Jacobian, measured rows used by the fit
    Jp_meas: np.ndarray  # (n, 3, P) at the measurements
    points_map: np.ndarray  # (N, 3) m
    Jp_map: np.ndarray  # (N, 3, P) at the estimate
    Jp_map_uncal: np.ndarray  # (N, 3, P) at the uncalibrated parameters
    residual_dim: int


def _axis_name(v: np.ndarray) -> str:
    i = int(np.argmax(np.abs(v)))
    return "xyz"[i] if abs(v[i]) > 0.95 else "(" + ", ".join(f"{c:+.2f}" for c in v) + ")"


def assess(inp: Inputs, tolerance_m: float | None = None, direction_advice=None) -> dict:
    """The `accuracy` document (see module docstring).  `direction_advice(axis_name)`: the
    system's words for how to measure along a direction (e.g. which jig faces to touch)."""
    free = np.asarray(inp.free, bool)
    A = P.absorption(inp.Jm, free)
    meas = P.predict(inp.Jp_meas, free, inp.cov_free, inp.prior_sigma, A)
    amap = P.predict(inp.Jp_map, free, inp.cov_free, inp.prior_sigma, A)
    before = P.uncalibrated(inp.Jp_map_uncal, inp.prior_sigma)
    sig, b95 = amap.sigma, amap.bound95
    contrib = P.fixed_contributions(inp.Jp_map, free, inp.prior_sigma, A)
    fixed_names = [n for n, f in zip(inp.names, free) if not f]
    top = sorted(zip(fixed_names, contrib), key=lambda t: -t[1])[:5]

    reasons, advice = [], []
    m, p = inp.Jm.shape[0], int(free.sum())
    if m < MIN_RESIDUALS_PER_PARAMETER * p:
        more = math.ceil((MIN_RESIDUALS_PER_PARAMETER * p - m) / inp.residual_dim)
        reasons.append(f"{m} residuals for {p} identified parameters (fewer than {MIN_RESIDUALS_PER_PARAMETER} each)")
        advice.append(f"record at least {more} more measurements, spread over the workspace")
    w, V = P.measured_directions(inp.Jm, inp.Jp_meas, inp.residual_dim)
    unmeasured = [V[:, i] for i in range(3) if w[i] < UNMEASURED_EIG]
    for v in unmeasured:
        ax = _axis_name(v)
        reasons.append(f"no measurement fixes the point along {ax}")
        advice.append(direction_advice(ax) if direction_advice else f"add measurements that fix the point along {ax}")
    worse = sig > before
    if worse.any():
        i = int(np.argmax(sig - before))
        reasons.append(f"predicted worse than the uncalibrated model at {int(worse.sum())} of {len(sig)} map points "
                       f"(e.g. {sig[i] * 1e3:.3g} vs {before[i] * 1e3:.3g} mm at "
                       f"({', '.join(f'{c * 1e3 + 0.0:.0f}' for c in inp.points_map[i])}) mm)")
        if not advice:
            advice.append("record more measurements near the worst map points")
    status = "insufficient" if reasons else "pass"
    tol = None
    if tolerance_m is not None:
        within = b95 <= tolerance_m
        tol = {"tolerance_m": float(tolerance_m), "points_within": int(within.sum()), "points": int(within.size),
               "worst_bound95_m": float(b95.max()), "status": "pass" if within.all() else "fail"}
        if not within.all() and status == "pass":
            status = "fail"
            reasons.append(f"95 % bound {b95.max() * 1e3:.3g} mm exceeds the tolerance {tolerance_m * 1e3:.3g} mm at "
                           f"{int((~within).sum())} of {within.size} map points")
            advice.append("record more measurements where the bound is largest, or relax the tolerance")
    rms = lambda a: float(np.sqrt(np.mean(np.square(a))))  # noqa: E731
    return {
        "status": status,
        "reason": "; ".join(reasons),
        "advice": "; ".join(advice),
        "residuals_per_parameter": m / max(p, 1),
        "measured_direction_eigenvalues": w,
        "at_measurements": {"rms_1sigma_m": rms(meas.sigma), "rms_1sigma_fit_m": rms(meas.sigma_fit),
                            "rms_1sigma_prior_m": rms(meas.sigma_prior)},
        "map": {"points_m": inp.points_map, "sigma_m": sig, "bound95_m": b95, "sigma_fit_m": amap.sigma_fit,
                "sigma_prior_m": amap.sigma_prior, "uncalibrated_sigma_m": before},
        "map_rms_1sigma_m": rms(sig), "map_max_1sigma_m": float(sig.max()), "map_max_bound95_m": float(b95.max()),
        "map_uncalibrated_rms_1sigma_m": rms(before),
        "fixed_parameter_contributions": [{"name": n, "rms_m": float(c)} for n, c in top if c > 1e-9],
        "tolerance": tol,
    }


def evaluate(model, x: np.ndarray, free: np.ndarray, cov_free: np.ndarray, data: dict, prior_sigma: np.ndarray,
             map_data: dict, x_uncal: np.ndarray, tolerance_m: float | None = None, direction_advice=None) -> dict:
    """`assess` for a `MeasurementModel` at estimate x (data: the measurements the fit used)."""
    J = model.jacobian(x, data)
    _, Jp_meas = model.points(x, data)
    pts, Jp_map = model.points(x, map_data)
    _, Jp_uncal = model.points(x_uncal, map_data)
    inp = Inputs(names=model.parameter_names(), free=np.asarray(free, bool),
                 cov_free=np.asarray(cov_free, float).reshape(int(np.sum(free)), int(np.sum(free))),
                 prior_sigma=np.asarray(prior_sigma, float), Jm=J.reshape(-1, J.shape[-1]), Jp_meas=Jp_meas,
                 points_map=pts, Jp_map=Jp_map, Jp_map_uncal=Jp_uncal, residual_dim=model.residual_dim)
    return assess(inp, tolerance_m, direction_advice)


def touch_advice(fixture: dict | None):
    """Direction advice of a touch jig: which faces fix a coordinate."""
    def advise(ax: str) -> str:
        faces = [f["id"] for f in (fixture or {}).get("faces", []) if f["axis"] == ax]
        where = f" (faces {', '.join(faces)})" if faces else ""
        return f"touch faces whose normal is along {ax}{where}: at least 3 contacts per such face"
    return advise
