"""Stage identify: nonlinear least squares (optionally robust loss) with outlier rejection
and k-fold held-out residuals.  Writes fit.json, residuals.parquet, history.json, model.json."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from pipeline.accuracy.propagate import fixture_covariance
from pipeline.identify.complexity import explain, relabel, select
from pipeline.identify.exports import describe, write_exports
from pipeline.identify.least_squares import FitOptions, cross_validate, holdout_warning, point_accuracy
from pipeline.identify.linear_folds import CLOSED_FORM_PARAMETERS, kfold_at
from pipeline.identify.model import take, uncalibrated
from pipeline.identify.natural_groups import holdout_groups
from pipeline.identify.outliers import fit_rejecting
from pipeline.identify.results import STATED_KIND, parameter_table, stated_uncertainty, with_3d
from pipeline.identify.plausibility import implausible, warnings_of
from pipeline.identify.shrinkage import shrinkage_document
from pipeline.ingest.tables import model_columns
from pipeline.recording.schemas import META_FIXTURE, META_ROBOT
from pipeline.stages.artefacts import read_json, write_json, write_table
from pipeline.stages.ingest import load_system, read_measurements

NAME = "identify"


def group_column(system, table: dict) -> np.ndarray:
    """Label of each measurement for per-group plots: the system's GROUP_COLUMN, else `face`,
    else the first string column, else the channel name."""
    n = len(table["record"])
    for c in (getattr(system, "GROUP_COLUMN", None), "face"):
        if c and c in table:
            return np.asarray(table[c]).astype(str).astype(object)
    for c, v in table.items():
        if np.asarray(v).dtype == object:
            return np.asarray(v).astype(str).astype(object)
    return np.full(n, system.MEASUREMENT_CHANNEL, dtype=object)


def options_of(params: dict, model=None, rec=None) -> FitOptions:
    """Solver settings from the stage's params; with the model and recording, each parameter's prior 1σ
    (the robot model file's prior_sigma, then `prior` — the CLI's --prior — over the defaults)."""
    prior = None
    if model is not None:
        from pipeline.accuracy.prior import prior_sigma

        file_priors = (rec.metadata.get(META_ROBOT, {}).get("prior_sigma") or {}) if rec is not None else {}
        asked = str(params.get("robot_class", "auto"))
        prior = prior_sigma(model, file_priors, params.get("prior") or {}, None if asked == "auto" else asked)[0]
    return FitOptions(loss=str(params.get("loss", "linear")), f_scale=float(params.get("f_scale_m", 1e-4)),
                      prior_sigma=prior)


def _progress(line: str) -> None:
    import sys

    print(f"identify: {line}", file=sys.stderr, flush=True)


def run(run_dir: Path, params: dict) -> dict:
    run_dir = Path(run_dir)
    from pipeline.dynamics.stage import identify as identify_dynamics, is_dynamics_run

    if is_dynamics_run(run_dir):  # effort recordings: the dynamics model family (pipeline.dynamics)
        return identify_dynamics(run_dir, params)
    out = run_dir / NAME
    system, model, rec = load_system(run_dir)
    table = read_measurements(run_dir)
    data = model_columns(table)
    opts = options_of(params, model, rec)
    selection = shrunk = None
    reference = model  # "before": the nominal robot, registration fitted, the tool as the campaign has it
    folds = int(params.get("folds", 5))
    grouped = bool(getattr(model, "groups", None) and model.groups())
    from pipeline.identify.route import resolve
    from pipeline.systems.urdf_robot import is_tree

    route = resolve(str(params.get("model_choice", "auto")), system.SYSTEM, model,
                    tree=system.SYSTEM == "urdf" and is_tree(rec))
    shown = grouped and system.SYSTEM == "urdf"  # seed systems: artefacts and output as they were
    if shown:
        _progress(f"model choice {route['route']} ({route['reason']})")
    if grouped and route["route"] == "shrinkage":  # every parameter, pulled toward nominal
        from pipeline.identify.outliers import RobustFit
        from pipeline.identify.shrinkage_fit import shrunk_fit

        f, shrunk, holdout_kept = shrunk_fit(model, data, opts, k=folds, seed=int(params.get("seed", 0)),
                                             progress=_progress)
        if shrunk.tool == "free":  # the left-out groups freed the tool point: the model estimates it (the RMS
            model = replace(model, fit_tool=True)  # before stays the tool as drawn: `reference`)
        rf = RobustFit(f, np.ones(len(table["record"]), bool))
        kept_data = data
    else:
        # whole URDF robots measured in lengths: candidates and the kept model's k-fold scored in closed form
        closed = (system.SYSTEM == "urdf" and getattr(model, "residual_unit", "m") == "m"
                  and len(model.parameter_names()) >= CLOSED_FORM_PARAMETERS)
        if grouped:  # keep only groups that improve held-out error
            selection = select(model, data, k=folds, seed=int(params.get("seed", 0)), options=opts, progress=_progress,
                               groups_of_rows=holdout_groups(model, data), closed_form=closed)
            opts = replace(opts, fixed=tuple(sorted(set(opts.fixed) | set(selection.fixed))))
        # the kept model, warm from its solution where the choice solved it (the start stays the model's own)
        warm = selection is not None and selection.x is not None
        rf = fit_rejecting(model, data, replace(opts, x0=selection.x) if warm else opts,
                           threshold=float(params.get("outlier_threshold", 5.0)))
        if warm:
            start = model.initial_guess(data) if hasattr(model, "initial_guess") else model.nominal()
            rf = replace(rf, fit=replace(rf.fit, nominal=np.asarray(start, float)))
        f = rf.fit
        if selection is not None:
            relabel(f, selection)
        kept_data = take(data, rf.kept)
        cv = kfold_at if closed else cross_validate
        holdout_kept = cv(model, kept_data, k=folds, seed=int(params.get("seed", 0)), options=opts,
                          groups=holdout_groups(model, kept_data), **({"solution": f} if closed else {}))
    extra = model.extra_metrics(f.nominal, f.x, kept_data) if hasattr(model, "extra_metrics") else None
    f, std_independent, resampled = stated_uncertainty(model, f, kept_data)  # a camera: the image jackknife
    if resampled:
        extra = (extra or {}) | resampled
    tip_sigma = point_accuracy(model, f, kept_data)

    n, k = len(table["record"]), model.residual_dim
    before = model.residuals(uncalibrated(reference, data), data).reshape(n, k)  # not the solver's start
    after = model.residuals(f.x, data).reshape(n, k)
    holdout = np.full((n, k), np.nan)
    holdout[rf.kept] = holdout_kept
    res = {"record": table["record"].astype(np.int64), "group": group_column(system, table),
           "used": rf.kept}
    if "timestamp_ns" in table:
        res["timestamp_ns"] = table["timestamp_ns"].astype(np.int64)
    for j in range(k):
        res[f"before_{j}"] = before[:, j]
        res[f"after_{j}"] = after[:, j]
        res[f"holdout_{j}"] = holdout[:, j]
    write_table(out / "residuals.parquet", res)

    rms = lambda a: float(np.sqrt(np.nanmean(a**2)))  # noqa: E731
    free = f.free
    doc = {
        "system": system.SYSTEM,
        "names": f.names, "units": f.units,
        "nominal": model.nominal(), "x0": f.nominal, "x": f.x, "std": f.std, "free": free,
        "reasons": {f.names[i]: r for i, r in sorted(f.identifiability.reasons.items())},
        "sigma_m": f.sigma, "cov": f.cov,
        "rejected_records": [r["record"] for r in rf.rejected], "rejected": rf.rejected,
        "loss": opts.loss, "f_scale_m": opts.f_scale, "outlier_threshold": float(params.get("outlier_threshold", 5.0)),
        "n_measurements": n, "n_used": int(rf.kept.sum()), "residual_dim": k,
        "rms_before_m": rms(before[rf.kept]), "rms_after_m": f.rms_after,
        "holdout_rms_m": rms(holdout_kept), "holdout_folds": folds,
        "max_abs_after_m": float(np.max(np.abs(f.residuals_after))),
        "n_parameters": len(f.names), "n_identifiable": int(free.sum()), "function_evaluations": f.nfev,
        "predicted_point_sigma_rms_m": float(np.sqrt(np.mean(tip_sigma**2))),
        "parameters": parameter_table(f),
        "warnings": [w for w in [holdout_warning(int(rf.kept.sum()), folds, k, int(free.sum()))] if w],
    }
    if getattr(model, "residual_unit", "m") != "m":  # a camera's residuals are px: the *_m figures are px then
        doc["residual_unit"] = model.residual_unit
    doc = with_3d(doc, model, take(data, rf.kept), before[rf.kept], after[rf.kept], holdout_kept)
    tol = (rec.metadata.get(META_FIXTURE) or {}).get("tolerance_m")
    if tol and "face" in kept_data:  # per-face machining error, shared by a face's contacts (not in σ̂²(JᵀJ)⁻¹)
        Jf = model.jacobian(f.x, kept_data).reshape(-1, f.x.size)[:, free]
        doc |= {"fixture_tolerance_m": float(tol),
                "cov_fixture": fixture_covariance(Jf, kept_data["face"], k, float(tol))}
    if selection is not None:
        doc["model_selection"] = {"kept_groups": selection.kept, "rounds": selection.rounds,
                                  "holdout_registration_only_m": selection.holdout_registration_m,
                                  "explanation": explain(selection, getattr(model, "residual_unit", "m"))}
    from pipeline.physics.summary import summarise

    physics = summarise(model, f, kept_data, opts, folds, int(params.get("seed", 0)), rms(holdout_kept))
    if physics is not None:  # geometry-only vs with-physics held-out, each kept term's reading
        doc["physics"] = physics
    if shown:  # which route the model choice took, and why (auto resolves per recording)
        doc["model_choice"] = route
    if shrunk is not None:
        doc["model_selection"] = shrinkage_document(shrunk)
        if shrunk.per_group:
            doc["holdout_kind"] = "whole groups left out (sessions, placements or sockets), own parameters refitted"
    if grouped:  # the nominal robot kept: said plainly, with the candidates tried and why none was kept
        from pipeline.identify.correction import document as correction, line

        corr = correction(model, f, selection, shrunk)
        if corr is not None:
            doc["correction"] = corr  # results.json: summary.correction and the status' reason (not a warning too)
            doc["status"] = "warn"
            if shown:
                _progress(line(corr))
    if extra is not None:  # optional system hook: system-specific figures
        doc["extra"] = extra
    if std_independent is not None:
        doc["std_kind"] = STATED_KIND
        doc["std_independent"] = std_independent
    if hasattr(model, "hand_eye_names"):  # a camera: the hand-eye transform and its stated σ, in the summary
        doc["hand_eye"] = hand_eye(model, f, std_independent)
    out.mkdir(parents=True, exist_ok=True)
    doc["exports"] = write_exports(model, f.x, out, f.std, f.free)
    write_json(out / "fit.json", doc)
    write_json(out / "history.json", {"cost_rms_m": f.history})
    write_json(out / "model.json", describe(model, f.x, f.std, f.free))
    keys = ("system", "n_measurements", "n_used", "rms_before_m", "rms_after_m", "holdout_rms_m",
            "holdout_folds", "max_abs_after_m", "sigma_m", "n_parameters", "n_identifiable", "rejected_records",
            "loss", "function_evaluations", "predicted_point_sigma_rms_m", "warnings")
    prior = opts.prior_sigma
    if prior is not None and grouped:  # the robot class whose compliance prior the estimates are judged by
        from pipeline.accuracy.prior import choose_class, prior_sigma

        cls = choose_class(model, f.x, f.free, str(params.get("robot_class", "auto")))
        if cls is not None:
            doc["prior_class"] = cls
            file_priors = rec.metadata.get(META_ROBOT, {}).get("prior_sigma") or {}
            prior = prior_sigma(model, file_priors, params.get("prior") or {}, cls["class"])[0]
            if shown:
                _progress(f"prior: robot class {cls['class']} ({cls['reason']})")
    if prior is not None and grouped:  # robot parameters beyond their prior: named, never a silent pass
        by_sign = tuple((shrunk.physics or {}).get("terms", ())) if shrunk is not None else ()
        doc["implausible"] = implausible(model, f.x, f.free, prior, by_sign)
        if doc["implausible"]:
            doc["warnings"] += warnings_of(doc["implausible"])
            doc["status"] = "warn"
    keys += tuple(k_ for k_ in ("status", "correction", "prior_class", "model_choice", "residual_unit", "hand_eye",
                                "rms_3d_before_m", "rms_3d_after_m", "holdout_rms_3d_m", "holdout_kind") if k_ in doc)
    return {k_: doc[k_] for k_ in keys} | {k_: doc[k_] for k_ in ("extra", "physics") if k_ in doc}


def hand_eye(model, f, std_independent: np.ndarray | None) -> dict:
    """{parameter: {estimate, sigma, sigma_kind, sigma_independent, unit}} of a camera's hand-eye transform."""
    out = {}
    for n in model.hand_eye_names():
        i = f.names.index(n)
        row = {"estimate": float(f.x[i]), "sigma": float(f.std[i]), "unit": f.units[i],
               "sigma_kind": "image jackknife" if std_independent is not None else "independent corners"}
        if std_independent is not None:
            row["sigma_independent"] = float(std_independent[i])
        out[n] = row
    return out


def read_fit(run_dir: Path) -> dict:
    return read_json(Path(run_dir) / NAME / "fit.json")
