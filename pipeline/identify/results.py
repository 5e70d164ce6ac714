"""results.json: the machine-readable figures of an identification (SI units)."""

from __future__ import annotations

import numpy as np

from pipeline import __version__
from pipeline.identify.least_squares import Fit


def parameter_table(fit: Fit) -> list[dict]:
    """One row per parameter: name, nominal, estimate, std, unit, identifiable, reason."""
    rows = []
    for i, name in enumerate(fit.names):
        row = {"name": name, "nominal": float(fit.nominal[i]), "estimate": float(fit.x[i]),
               "std": float(fit.std[i]), "unit": fit.units[i], "identifiable": bool(fit.free[i])}
        if not fit.free[i]:
            row["reason"] = fit.identifiability.reasons.get(i, "")
        rows.append(row)
    return rows


STATED_KIND = ("delete-one-image jackknife (the corners of an image share its robot-pose error), plus the "
               "independent-row σ̂²(JᵀJ)⁻¹ for the directions the resampling cannot reach")


def stated_uncertainty(model, fit: Fit, data) -> tuple[Fit, np.ndarray | None, dict]:
    """The uncertainty a run states, for a model whose rows share errors the fit's independent-row
    σ̂²(JᵀJ)⁻¹ does not see (a camera: its ``resampled_covariance`` hook, the image jackknife):
    (`fit` with cov = resampled + independent-row covariance of the free parameters and std its
    diagonal's root, the independent-row std it replaces (P,), {"jackknife_sigma": {name: σ}});
    `fit` unchanged, None, {} for other models."""
    from dataclasses import replace

    hook = getattr(model, "resampled_covariance", None)
    C = hook(fit.x, fit.free, data) if hook is not None else None
    if C is None:
        return fit, None, {}
    free = np.flatnonzero(fit.free)
    cov = np.asarray(C, float) + np.asarray(fit.cov, float)
    std = np.zeros(len(fit.names))
    std[free] = np.sqrt(np.clip(np.diag(cov), 0, None))
    jk = {fit.names[i]: float(np.sqrt(max(C[j, j], 0.0))) for j, i in enumerate(free)}
    return replace(fit, std=std, cov=cov), np.asarray(fit.std, float), {"jackknife_sigma": jk}


def results_document(system: str, fit: Fit, holdout: np.ndarray, tip_sigma: np.ndarray, *,
                     elapsed_s: float, source: dict, warnings: list[str], k_folds: int) -> dict:
    """Gather the figures of one calibration run."""
    return {
        "system": system,
        "robocal_version": __version__,
        "source": source,
        "n_measurements": int(fit.residuals_after.shape[0]),
        "residual_dim": int(fit.residuals_after.shape[1]),
        "rms_before_m": fit.rms_before,
        "rms_after_m": fit.rms_after,
        "max_abs_after_m": float(np.max(np.abs(fit.residuals_after))),
        "holdout_rms_m": float(np.sqrt(np.nanmean(holdout**2))),
        "holdout_folds": k_folds,
        "sigma_m": fit.sigma,
        "n_parameters": len(fit.names),
        "n_identifiable": int(fit.free.sum()),
        "elapsed_s": elapsed_s,
        "solve_time_s": fit.elapsed_s,
        "function_evaluations": fit.nfev,
        "predicted_point_accuracy": {  # superseded by "accuracy"; kept for readers of older results.json
            "superseded_by": "accuracy (map_rms_1sigma_m, map_max_bound95_m): the one stated accuracy",
            "rms_1sigma_m": float(np.sqrt(np.mean(tip_sigma**2))),
            "max_1sigma_m": float(np.max(tip_sigma)),
            "note": ("SUPERSEDED, not the stated accuracy (see `accuracy`): fit covariance only, no priors of fixed "
                     "parameters, no held-out check. 3-D 1σ error of the calibrated model's point (tool tip) at the measured "
                     "configurations, from the parameter covariance. Each measurement may fix fewer "
                     "than 3 coordinates (a touch fixes one), so this 3-D figure, not the residual "
                     "RMS, is the accuracy a user gets."),
        },
        "parameters": parameter_table(fit),
        "warnings": warnings,
    }


def rms_3d(model, residuals: np.ndarray, data) -> float | None:
    """RMS over measurements of the norm of the 3-D position error (m): the figure a user compares with
    other tools'.  URDF points, poses (position part) and coincidences (touch rows, not the known-distance
    rows); None for other models (planes, seed systems: their residual is not a 3-D error)."""
    if getattr(model, "system", None) != "urdf" or model.residual_dim not in (3, 6):
        return None
    r = np.asarray(residuals, float).reshape(-1, model.residual_dim)[:, :3]
    rows = np.asarray(data.get("kind", np.zeros(len(r), int))) == 0
    ok = rows & np.all(np.isfinite(r), axis=1)
    return float(np.sqrt(np.mean(np.sum(r[ok] ** 2, axis=1)))) if ok.any() else None


def with_3d(doc: dict, model, data, before, after, holdout) -> dict:
    """Add the 3-D headline (`rms_3d_*`) to a results document, where the model has one; the k-fold
    held-out figure is labelled as held out within this one recording."""
    v = {"rms_3d_before_m": rms_3d(model, before, data), "rms_3d_after_m": rms_3d(model, after, data),
         "holdout_rms_3d_m": rms_3d(model, holdout, data)}
    if v["rms_3d_after_m"] is None:
        return doc
    return doc | v | {"holdout_kind": "k-fold, rows of this recording held out (same session, same instrument "
                                      "placement); other sessions: robocal evaluate"}
