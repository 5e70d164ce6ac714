"""`robocal calibrate`: recording → identified model, results.json and model.json."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError
from pipeline.identify.least_squares import FitOptions, cross_validate, fit, holdout_warning, point_accuracy
from pipeline.identify.results import results_document
from pipeline.recording.reader import read_recording
from pipeline.stages.artefacts import sha256_file
from pipeline.systems.registry import detect, load_with_physics


def calibrate(path: str | Path, out: str | Path, options: FitOptions = FitOptions(), k_folds: int = 5,
              seed: int = 0, solver: str = "lm", joint_offsets: bool = False, variant: str | None = None,
              select_groups: bool = True, accuracy: dict | None = None, physics: str | None = None,
              payload: list[str] | None = None, model_choice: str = "groups") -> dict:
    """Read, identify, cross-validate; write DIR/results.json and DIR/model.json.

    `solver`: 'lm' (least squares, default) or 'ga' (seed 001's genetic algorithm, for systems
    whose model offers `batch_cost_fn`).  `joint_offsets`: also identify the arm's joint
    offsets (systems whose model has a `joint_offsets` field).  `variant`: the model variant
    (systems whose model has a `variant` field, e.g. delta-tracker: simplified, extended).  `physics`,
    `payload`: gravity terms of a URDF robot (`pipeline.physics.compliance`)."""
    t0 = time.perf_counter()
    from pipeline.identify.route import check, resolve
    from pipeline.systems.urdf_robot import is_tree

    check(model_choice)
    path, out = Path(path), Path(out)
    rec = read_recording(path)
    system = detect(rec)
    model, table = load_with_physics(system, rec, physics, payload)
    if joint_offsets:
        if not hasattr(model, "joint_offsets"):
            raise RobocalError(f"{path}: system {system.SYSTEM} does not support --joint-offsets")
        import dataclasses
        model = dataclasses.replace(model, joint_offsets=True)
    if variant is not None:  # e.g. the Delta's "extended" error model
        if not hasattr(model, "variant"):
            raise RobocalError(f"{path}: system {system.SYSTEM} has no model variants (--model-variant)")
        import dataclasses
        try:
            model = dataclasses.replace(model, variant=variant)
        except ValueError as e:
            raise RobocalError(f"{path}: {e}") from None
    from dataclasses import replace as dataclasses_replace

    from pipeline.accuracy.prior import prior_sigma
    from pipeline.recording.schemas import META_ROBOT

    # check the priors (model file, --prior) before the work, so a typo fails at once
    sigma0 = prior_sigma(model, rec.metadata.get(META_ROBOT, {}).get("prior_sigma") or {},
                         (accuracy or {}).get("prior") or {})[0]
    if options.prior_sigma is None:  # the fit judges a parameter freed off the nominal geometry against it
        options = dataclasses_replace(options, prior_sigma=sigma0)
    from pipeline.recording.schemas import META_CAMPAIGN
    from pipeline.validate.plausibility import screen

    _joint_limits(path, rec, system, table)  # the check `robocal run`'s validate applies: the same verdict
    gross = screen(model, table, rec.metadata.get(META_CAMPAIGN, {}), options)  # before any open-ended solve
    if gross["status"] == "fail":
        raise RobocalError(f"{path}: {gross['message']}")
    route = resolve(model_choice, system.SYSTEM, model, tree=system.SYSTEM == "urdf" and is_tree(rec))
    model_choice = route["route"]
    if solver == "ga":
        from pipeline.identify.genetic import cross_validate_ga, fit_ga
        if not hasattr(model, "batch_cost_fn"):
            raise RobocalError(f"{path}: system {system.SYSTEM} has no genetic-algorithm solver (use --solver lm)")
        f = fit_ga(model, table)
        holdout = cross_validate_ga(model, table, k=k_folds, seed=seed)
    elif solver == "lm" and model_choice == "shrinkage" and getattr(model, "groups", None) and model.groups():
        from pipeline.identify.shrinkage_fit import shrunk_fit

        selection = None
        f, shrunk, holdout = shrunk_fit(model, table, options, k=k_folds, seed=seed)
        if shrunk.tool == "free":  # the left-out groups freed the tool point: the model estimates it
            from dataclasses import replace as _replace

            model = _replace(model, fit_tool=True)
    elif solver == "lm":
        selection = None
        if select_groups and getattr(model, "groups", None) and model.groups():
            from dataclasses import replace as _replace

            from pipeline.identify.complexity import select
            selection = select(model, table, k=k_folds, seed=seed, options=options)
            options = _replace(options, fixed=tuple(sorted(set(options.fixed) | set(selection.fixed))))
        f = fit(model, table, options)
        if selection is not None:
            from pipeline.identify.complexity import relabel
            relabel(f, selection)
        holdout = cross_validate(model, table, k=k_folds, seed=seed, options=options)
    else:
        raise RobocalError(f"unknown solver {solver!r} (expected lm or ga)")
    from pipeline.identify.results import STATED_KIND, stated_uncertainty

    f, std_independent, resampled = stated_uncertainty(model, f, table)  # a camera: the image jackknife σ
    tip_sigma = point_accuracy(model, f, table)
    warnings = list(rec.warnings)
    if w := holdout_warning(len(holdout), k_folds, model.residual_dim, int(f.free.sum())):
        warnings.append(w)
    doc = results_document(system.SYSTEM, f, holdout, tip_sigma, elapsed_s=time.perf_counter() - t0,
                           source={"path": str(path), "sha256": sha256_file(path)}, warnings=warnings,
                           k_folds=k_folds)
    doc["solver"] = solver
    from pipeline.identify.results import with_3d

    if getattr(model, "residual_unit", "m") != "m":  # a camera's residuals are px: the *_m figures are px then
        doc["residual_unit"] = model.residual_unit
    doc = with_3d(doc, model, table, f.residuals_before, f.residuals_after, holdout)
    if solver == "lm" and selection is not None:
        from pipeline.identify.complexity import explain
        doc["model_selection"] = {"kept_groups": selection.kept, "rounds": selection.rounds,
                                  "holdout_registration_only_m": selection.holdout_registration_m,
                                  "explanation": explain(selection, getattr(model, "residual_unit", "m"))}
    if solver == "lm":
        from pipeline.physics.summary import summarise

        physics_doc = summarise(model, f, table, options, k_folds, seed, float(np.sqrt(np.nanmean(holdout**2))))
        if physics_doc is not None:  # geometry-only vs with-physics held-out, each kept term's reading
            doc["physics"] = physics_doc
    if solver == "lm" and model_choice == "shrinkage" and selection is None and "shrunk" in locals():
        from pipeline.identify.shrinkage import shrinkage_document

        doc["model_selection"] = shrinkage_document(shrunk)
        if shrunk.per_group:
            doc["holdout_kind"] = "whole groups left out (sessions, placements or sockets), own parameters refitted"
    if solver == "lm" and system.SYSTEM == "urdf" and getattr(model, "groups", None) and model.groups():
        doc["model_choice"] = route  # which route the model choice took, and why (auto resolves per recording)
    from pipeline.accuracy.stage import guarded_document

    from pipeline.identify.folds import design_folds

    from pipeline.identify.natural_groups import holdout_groups

    folds = design_folds(len(holdout), k_folds, seed, holdout_groups(model, table), table)
    acc = guarded_document(model, rec, f.x, f.free, f.cov, table, accuracy or {}, (holdout, folds),
                           f.sigma if "shrunk" in locals() else None)  # a shrinkage fit: its σ̂ is the scatter
    if (accuracy or {}).get("previous"):
        from pipeline.accuracy.previous import compare, read_parameters

        acc["previous"] = {"run": str(accuracy["previous"]),
                           **compare(doc["parameters"], read_parameters(Path(accuracy["previous"])))}
    doc["accuracy"] = acc
    doc["status"] = acc["status"]
    doc["status_reason"], doc["status_advice"] = acc["reason"], acc["advice"]
    from pipeline.identify.plausibility import implausible as find_implausible, warnings_of

    implausible = []
    if solver == "lm" and getattr(model, "groups", None) and model.groups():  # URDF robots
        by_sign = tuple((shrunk.physics or {}).get("terms", ())) if "shrunk" in locals() else ()
        implausible = doc["implausible"] = find_implausible(model, f.x, f.free, options.prior_sigma, by_sign)
        doc["warnings"] += warnings_of(implausible)
    if implausible and doc["status"] == "pass":  # never a silent pass over a parameter beyond its prior
        doc["status"] = "warn"
        doc["status_reason"] = (f"{len(implausible)} parameter(s) estimated beyond 3 prior σ from nominal: "
                                + ", ".join(p["name"] for p in implausible))
        doc["status_advice"] = "check the robot description and the data; or widen the prior (--prior) if intended"
    if hasattr(model, "extra_metrics"):  # optional hook: system-specific validation figures
        doc.update(model.extra_metrics(f.nominal, f.x, table))
    if std_independent is not None:  # the parameters' std is the resampling σ; what σ̂²(JᵀJ)⁻¹ says, beside it
        doc |= resampled | {"std_kind": STATED_KIND}
        for row, s in zip(doc["parameters"], std_independent):
            row["std_independent"] = float(s)
    out.mkdir(parents=True, exist_ok=True)
    from pipeline.identify.exports import describe, write_exports
    (out / "model.json").write_text(json.dumps(describe(model, f.x, f.std, f.free), indent=2) + "\n")
    doc["exports"] = write_exports(model, f.x, out, f.std, f.free)
    from pipeline.stages.artefacts import dumps

    (out / "results.json").write_text(dumps(doc))  # numpy-aware (the accuracy map), NaN → null
    return doc


def _joint_limits(path: Path, rec, system, table: dict) -> None:
    """Refuse measurements outside the robot model's joint limits, as `robocal run` (validate) does."""
    from pipeline.stages.validate import _limits
    from pipeline.validate.checks import FAIL, check_joint_limits

    lim = _limits(rec, system)
    if lim is None or "joint_positions" not in table:
        return
    lo, hi, names = lim
    q = np.asarray(table["joint_positions"], float)
    if q.ndim != 2 or q.shape[1] != len(lo):
        return
    rec_ids = np.asarray(table.get("record", np.arange(len(q))))
    c = check_joint_limits(system.MEASUREMENT_CHANNEL if hasattr(system, "MEASUREMENT_CHANNEL") else "measurements",
                           q, rec_ids, lo, hi, names)
    if c.status == FAIL:
        raise RobocalError(f"{path}: joint_limits: {c.message}")


def summary_rows(doc: dict) -> list[tuple[str, str]]:
    """Display rows (mm for lengths) of a results document."""
    from pipeline.report.labels import residual_text

    mm = lambda v: f"{v * 1e3:.4f} mm"  # noqa: E731
    res = lambda v: residual_text(v, doc.get("residual_unit"))  # noqa: E731 — px for a camera
    axis = " (per axis)" if doc.get("rms_3d_after_m") is not None else ""
    return [
        ("system", doc["system"]),
        ("measurements", str(doc["n_measurements"])),
        ("RMS before" + axis, res(doc["rms_before_m"])),
        ("RMS after" + axis, res(doc["rms_after_m"])),
        (f"held-out RMS ({doc['holdout_folds']}-fold CV){axis}", res(doc["holdout_rms_m"])),
        *([("RMS of the 3-D error before / after", f"{mm(doc['rms_3d_before_m'])} / {mm(doc['rms_3d_after_m'])}"),
           ("held-out RMS of the 3-D error (" + ("whole groups left out" if str(doc.get("holdout_kind", "")).startswith(
               "whole") else f"{doc['holdout_folds']}-fold, within this recording") + ")",
            mm(doc["holdout_rms_3d_m"]))] if doc.get("rms_3d_after_m") is not None else []),
        ("max |residual| after", res(doc["max_abs_after_m"])),
        *([("predicted over the workspace (1σ RMS / worst 95 %)",
            f"{mm(doc['accuracy']['map_rms_1sigma_m'])} / {mm(doc['accuracy']['map_max_bound95_m'])}")]
          if "map_rms_1sigma_m" in doc.get("accuracy", {}) else []),
        *([(NEW_LABEL, mm(doc["accuracy"]["new_measurement"]["rms_3d_m"]))]
          if "new_measurement" in doc.get("accuracy", {}) else []),
        *([("status", doc["status"])] if "status" in doc else []),
        ("parameters identified / total", f"{doc['n_identifiable']} / {doc['n_parameters']}"),
        *([("model choice", f"{doc['model_choice']['route']} (--model-choice {doc['model_choice']['asked']})")]
          if "model_choice" in doc else []),
        ("solve time", f"{doc['solve_time_s']:.3f} s"),
    ]


NEW_LABEL = "predicted for a new session or posture, measured as here (RMS 3-D)"

__all__ = ["calibrate", "summary_rows", "NEW_LABEL"]
