"""The accuracy verdict of a calibration: map, status, reason, advice (functional core).

Status ``insufficient`` (never ``pass``) when the data do not carry the information
(`information`: distinct measurements, not rows):
* fewer than MIN_DOF distinct residuals beyond the identified parameters (σ̂ undetermined;
  repeated rows do not count);
* a direction of the point no measurement fixes (a touch campaign without an x-facing face);
* the calibrated model is predicted worse than the uncalibrated one somewhere on the map;
* the campaign taught little: the map's 1σ RMS above TAUGHT_MAX of the uncalibrated one.
Status ``warn`` (never ``pass``) when the run's own held-out error exceeds what the stated σ
implies beyond chance (`holdout`): every stated 1σ and bound is then inflated by √R.
With a tolerance, ``fail`` when the 95 % bound exceeds it anywhere on the map.

With few residual degrees of freedom the fitted covariance is scaled by the 95 % upper bound of
σ²/σ̂² (`information.fit_inflation`); with none (the fit interpolates its data) the stated 1σ at a
map point is no better than the uncalibrated model's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.accuracy import information as I, propagate as P
from pipeline.accuracy.condition import fixed_moment

TAUGHT_MAX = 0.5  # calibrated map 1σ RMS / uncalibrated above this: the campaign taught little
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
    holdout: dict | None = None  # `holdout.consistency` of the run's cross-validation, if any
    Jp_full: np.ndarray | None = None  # (N, 3, P) where a campaign could measure (default: the map)
    residual_unit: str = "m"  # of the measurements' residuals (px for a camera; the map's points stay m)
    residuals: np.ndarray | None = None  # (m·k,) in-sample at the estimate: the fixed parameters conditioned on them


def _axis_name(v: np.ndarray) -> str:
    i = int(np.argmax(np.abs(v)))
    return "xyz"[i] if abs(v[i]) > 0.95 else "(" + ", ".join(f"{c:+.2f}" for c in v) + ")"


def assess(inp: Inputs, tolerance_m: float | None = None, direction_advice=None) -> dict:
    """The `accuracy` document (see module docstring).  `direction_advice(axis_name)`: the
    system's words for how to measure along a direction (e.g. which jig faces to touch)."""
    free = np.asarray(inp.free, bool)
    A = P.absorption(inp.Jm, free)
    mom = None if inp.residuals is None else fixed_moment(inp.Jm, free, inp.prior_sigma, inp.residuals)
    meas = P.predict(inp.Jp_meas, free, inp.cov_free, inp.prior_sigma, A, mom)
    amap = P.predict(inp.Jp_map, free, inp.cov_free, inp.prior_sigma, A, mom)
    before = P.uncalibrated(inp.Jp_map_uncal, inp.prior_sigma)
    sig, b95 = amap.sigma, amap.bound95
    contrib = P.fixed_contributions(inp.Jp_map, free, inp.prior_sigma, A, mom)
    fixed_names = [n for n, f in zip(inp.names, free) if not f]
    top = sorted(zip(fixed_names, contrib), key=lambda t: -t[1])[:5]

    reasons, advice = [], []
    info = I.information(inp.Jm, free, inp.residual_dim, inp.Jp_map if inp.Jp_full is None else inp.Jp_full,
                         inp.names)
    m, p = info.residuals_distinct, info.p
    more = I.more_needed(info, inp.residual_dim)
    if info.dof < I.MIN_DOF:
        rep = (f"{info.n_measurements} measurements at {info.n_distinct} distinct configuration(s) (repeated rows "
               f"add no information): " if info.n_distinct < info.n_measurements else "")
        reasons.append(f"{rep}{m} residuals for {p} identified parameters ({info.dof} degrees of freedom left, "
                       f"fewer than {I.MIN_DOF}: the noise level and the parameters' covariance are not determined)")
        advice.append(f"record at least {more} more measurements at distinct configurations, spread over the workspace (a full model "
                      f"identifies {info.p_full} of {info.n_parameters} parameters and needs about "
                      f"{max(I.COMFORT_PER_PARAMETER * info.p_full, info.p_full + I.MIN_DOF)} distinct residuals)")
    inflate_fit = I.fit_inflation(info.dof)
    if math.isfinite(inflate_fit) and inflate_fit != 1.0:  # σ̂ from few degrees of freedom: its 95 % upper bound
        cov_scaled = np.asarray(inp.cov_free, float) * inflate_fit
        meas = P.predict(inp.Jp_meas, free, cov_scaled, inp.prior_sigma, A, mom)
        amap = P.predict(inp.Jp_map, free, cov_scaled, inp.prior_sigma, A, mom)
        sig, b95 = amap.sigma, amap.bound95
    cov_used = np.asarray(inp.cov_free, float) * (inflate_fit if math.isfinite(inflate_fit) else 1.0)
    field = P.field_scale(inp.Jp_map, free, cov_used, inp.prior_sigma, A, b95, moment=mom)
    b95 = b95 * field  # ≥ 95 % of the map within it in 99 % of calibrations
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
    if not math.isfinite(inflate_fit):  # the fit interpolates its data: nothing better than the prior is known
        b_unc = P.norm_quantile(P.uncalibrated_cov(inp.Jp_map_uncal, inp.prior_sigma), 0.95)
        sig, b95 = np.maximum(sig, before), np.maximum(b95, b_unc)
    rms = lambda a: float(np.sqrt(np.mean(np.square(a))))  # noqa: E731
    taught = rms(sig) / max(rms(before), 1e-300)
    if taught > TAUGHT_MAX and not worse.any() and info.dof >= I.MIN_DOF:
        reasons.append(f"the campaign taught little: predicted 1σ over the map {rms(sig) * 1e3:.3g} mm against "
                       f"{rms(before) * 1e3:.3g} mm uncalibrated ({taught * 100:.0f} %)")
        advice.append(f"record measurements that fix the parameters limiting the map "
                      f"({', '.join(n for n, c in top[:3] if c > 1e-9) or 'see the fixed parameters'}), spread "
                      f"over the workspace")
    status = "insufficient" if reasons else "pass"
    ho = inp.holdout
    if ho is not None and not ho.get("consistent", True):
        f = float(ho["inflation"])
        sig, b95 = sig * f, b95 * f
        meas_scale = f
        k, u = (1.0, "px") if inp.residual_unit == "px" else (1e3, "mm")  # the residuals' unit
        reasons.append(f"held-out error contradicts the stated accuracy: held-out RMS {ho['holdout_rms_m'] * k:.3g} {u} "
                       f"where σ̂ and the design predict {ho['predicted_holdout_rms_m'] * k:.3g} {u} (ratio of mean "
                       f"squares {ho['ratio']:.2f}, p = {ho['p_value']:.2g}): the errors are not independent with one σ "
                       f"(noise that differs between measurements, errors shared between them) or the model misses an "
                       f"effect; stated accuracy inflated ×{f:.2f}")
        advice.append("see the diagnosis for the missing effect; the held-out error, not the fit's σ, is the accuracy")
        if status == "pass":
            status = "warn"
    else:
        meas_scale = 1.0
    tol = None
    if tolerance_m is not None:
        within = b95 <= tolerance_m
        tol = {"tolerance_m": float(tolerance_m), "points_within": int(within.sum()), "points": int(within.size),
               "worst_bound95_m": float(b95.max()), "status": "pass" if within.all() else "fail"}
        if not within.all() and status in ("pass", "warn"):
            status = "fail"
            reasons.append(f"95 % bound {b95.max() * 1e3:.3g} mm exceeds the tolerance {tolerance_m * 1e3:.3g} mm at "
                           f"{int((~within).sum())} of {within.size} map points")
            advice.append("record more measurements where the bound is largest, or relax the tolerance")
    return {
        "status": status,
        "reason": "; ".join(reasons),
        "advice": "; ".join(advice),
        "residuals_per_parameter": m / max(p, 1),
        "bound95_field_factor": field,
        "information": info.to_dict() | {"fit_covariance_factor": inflate_fit if math.isfinite(inflate_fit) else None,
                                         "map_over_uncalibrated": taught},
        "holdout_check": ho,
        "measured_direction_eigenvalues": w,
        "at_measurements": {"rms_1sigma_m": rms(meas.sigma) * meas_scale, "rms_1sigma_fit_m": rms(meas.sigma_fit),
                            "rms_1sigma_prior_m": rms(meas.sigma_prior)},
        "map": {"points_m": inp.points_map, "sigma_m": sig, "bound95_m": b95, "sigma_fit_m": amap.sigma_fit,
                "sigma_prior_m": amap.sigma_prior, "uncalibrated_sigma_m": before},
        "map_rms_1sigma_m": rms(sig), "map_max_1sigma_m": float(sig.max()), "map_max_bound95_m": float(b95.max()),
        "map_uncalibrated_rms_1sigma_m": rms(before),
        "fixed_parameter_contributions": [{"name": n, "rms_m": float(c)} for n, c in top if c > 1e-9],
        "tolerance": tol,
    }


def evaluate(model, x: np.ndarray, free: np.ndarray, cov_free: np.ndarray, data: dict, prior_sigma: np.ndarray,
             map_data: dict, x_uncal: np.ndarray, tolerance_m: float | None = None, direction_advice=None,
             holdout: tuple[np.ndarray, list[np.ndarray]] | None = None, robot_meta: dict | None = None,
             sigma_m: float | None = None) -> dict:
    """`assess` for a `MeasurementModel` at estimate x (data: the measurements the fit used).
    `holdout`: (held-out residuals (n, k) m of the run's cross-validation over `data`, the
    measurement indices of each fold), tested against σ̂ and the design (`holdout.consistency`).
    `robot_meta`: the recording's robot model (its ``repeatability_3sigma_m``, `noise.repeatability`).
    `sigma_m`: the fit's σ̂ per axis where its covariance is not σ̂²-scaled by its effective parameters (a
    shrinkage fit's, `condition.shrunk_moment`): one measurement's scatter is then √3·σ̂ itself."""
    J = model.jacobian(x, data)
    free = np.asarray(free, bool)
    Jf = J.reshape(-1, J.shape[-1])[:, free]
    cov_free = np.asarray(cov_free, float).reshape(int(free.sum()), int(free.sum()))
    from pipeline.accuracy import noise
    from pipeline.accuracy.holdout import basis, consistency

    e = model.residuals(x, data)
    groups = noise.configuration_groups(data)
    shared = None
    if groups is not None:
        cols, wts = noise.pose_columns(model.parameter_names(), model.parameter_units())
        shared = noise.estimate(basis(Jf), e, groups, model.residual_dim, J.reshape(-1, J.shape[-1])[:, cols], wts,
                                noise.repeatability(robot_meta or {}, getattr(model, "system", "")))
    if shared is not None and shared["tau_m"] > 0:  # an error shared by a configuration's measurements
        cov_free = noise.sandwich(Jf, shared["sigma_w_m"], shared["tau_m"], shared["B"])
        sigma_m = None  # the scatter then follows the sandwich, as for any fit
    ho = None
    if holdout is not None:
        ho = consistency(Jf, e, holdout[0], holdout[1], model.residual_dim, groups=groups, shared=shared)
    pts_meas, Jp_meas = model.points(x, data)
    pts, Jp_map = model.points(x, map_data)
    _, Jp_uncal = model.points(x_uncal, map_data)
    Jp_full = None
    if getattr(model, "system", "") not in ("arc-welder", "delta-tracker", "scorbot-scanner"):
        from pipeline.accuracy.workspace import spread_table

        spread = spread_table(model, data)
        Jp_full = None if spread is None else model.points(x, spread)[1]
    if not getattr(model, "fixes_frame", True):  # coincidences: the error of the points relative to each other
        Jp_meas = P.modulo_rigid(pts_meas, Jp_meas)
        Jp_map, Jp_uncal = P.modulo_rigid(pts, Jp_map), P.modulo_rigid(pts, Jp_uncal)
    inp = Inputs(names=model.parameter_names(), free=np.asarray(free, bool),
                 cov_free=cov_free,
                 prior_sigma=np.asarray(prior_sigma, float), Jm=J.reshape(-1, J.shape[-1]), Jp_meas=Jp_meas,
                 points_map=pts, Jp_map=Jp_map, Jp_map_uncal=Jp_uncal, residual_dim=model.residual_dim, holdout=ho,
                 Jp_full=Jp_full, residual_unit=getattr(model, "residual_unit", "m"), residuals=e.reshape(-1))
    doc = assess(inp, tolerance_m, direction_advice)
    if inp.residual_unit == "m" and model.residual_dim == 3:  # the residual is the 3-D point's error
        doc["new_measurement"] = new_measurement(doc, Jf, cov_free, e, sigma_m)
    if shared is not None:
        doc["shared_error"] = {"sigma_w_m": shared["sigma_w_m"], "tau_m": shared["tau_m"],
                               "tau_source": shared["tau_source"],
                               "configurations": int(np.unique(groups).size),
                               "note": "measurements at one configuration share an error (the robot's repeatability "
                                       "at that pose): Ω = σ_w² I + τ² B; the fitted parameters' covariance is the "
                                       "sandwich J⁺ΩJ⁺ᵀ" + ("" if shared["tau_m"] > 0 else " (τ = 0: not used)")}
    return doc


def new_measurement(doc: dict, Jf: np.ndarray, cov_free: np.ndarray, residuals: np.ndarray,
                    sigma_m: float | None = None) -> dict:
    """The predicted RMS 3-D error of a new measurement at a new configuration, measured as in this
    campaign (what `robocal evaluate` reports for a new session, and what held-out residuals measure):
    the model's error over the map (`map_rms_1sigma_m`) plus the scatter of one measurement about the
    model, √3·σ̂ per point, σ̂² = (|e|² + tr J_f Σ_f J_fᵀ) / m — the residual mean square with the fit's
    effective number of parameters (exact for least squares), or the fit's own σ̂ where given (`sigma_m`: a
    shrinkage fit, whose Σ_f is its error's second moment under the stated prior, not σ̂²-scaled).
    That scatter is the instrument's noise and the robot's error the model does not carry (free play,
    non-repeatability); both inflated by the held-out check's factor like the map.  Residuals (m, 3) m."""
    e = np.asarray(residuals, float).reshape(-1)
    if sigma_m is not None:
        s2 = float(sigma_m) ** 2
    else:
        s2 = (float(e @ e) + float(np.einsum("ij,jk,ik->", Jf, np.asarray(cov_free, float), Jf))) / max(e.size, 1)
    ho = doc.get("holdout_check") or {}
    f = float(ho.get("inflation", 1.0)) if not ho.get("consistent", True) else 1.0
    scatter = float(np.sqrt(3.0 * s2)) * f
    model_rms = float(doc["map_rms_1sigma_m"])
    return {"rms_3d_m": float(np.hypot(model_rms, scatter)), "model_rms_3d_m": model_rms, "scatter_rms_3d_m": scatter,
            "label": "a new measurement at a new configuration (a new session, placement or posture), measured as in "
                     "this campaign: the model's error over the map and one measurement's scatter about the model "
                     "(instrument noise and the robot's unmodelled error); compare with `robocal evaluate`"}


def touch_advice(fixture: dict | None):
    """Direction advice of a touch jig: which faces fix a coordinate."""
    def advise(ax: str) -> str:
        faces = [f["id"] for f in (fixture or {}).get("faces", []) if f["axis"] == ax]
        where = f" (faces {', '.join(faces)})" if faces else ""
        return f"touch faces whose normal is along {ax}{where}: at least 3 contacts per such face"
    return advise
