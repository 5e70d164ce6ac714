"""The `diagnose` stage: DIR/diagnose/diagnosis.json (contract: docs/reference/artefacts.md).

Reads the recording named by DIR/ingest/recording.json (its fixture and campaign metadata)
and the encoder stream ingest decoded (DIR/ingest/encoder.parquet: the diagnosis needs the
stream around each measurement; decoding the MCAP's JSON batches again would cost more than
the diagnosis itself) and starts from DIR/identify/fit.json when it
exists (its solution and rejected records).  Params: ``alpha`` (family α, 0.01), ``folds`` (5),
``block`` (measurements per cross-validation group, 5), ``n_boot`` (40), ``seed`` (0).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from pipeline.diagnose.method import Settings

NAME = "diagnose"
PHYSICS_SUFFIXES = (".compliance", ".lateral1", ".lateral2", ".compliance_load")
SUPPORTED = ("arc-welder", "delta-tracker", "scorbot-scanner", "urdf")
PROGRESS_LOG = "progress.log"  # DIR/diagnose/progress.log: the progress lines when stderr is not a terminal


def settings_of(params: dict) -> Settings:
    d = Settings()
    return Settings(alpha=float(params.get("alpha", d.alpha)), folds=int(params.get("folds", d.folds)),
                    block=int(params.get("block", d.block)), n_boot=int(params.get("n_boot", d.n_boot)),
                    seed=int(params.get("seed", d.seed)),
                    repeatability_3sigma_m=(None if params.get("repeatability_3sigma_m") is None
                                            else float(params["repeatability_3sigma_m"])))


def diagnose_recording(rec, settings: Settings = Settings(), x0: np.ndarray | None = None,
                       drop_records: list[int] | None = None, stream=None, physics: dict | None = None,
                       held: tuple[str, ...] | None = None, chosen: bool = False,
                       identified: dict | None = None) -> dict:
    """Diagnosis document of a decoded recording (arc welder, Delta + laser tracker, SCORBOT scanner);
    `stream`: its encoder stream when already decoded (the ingest stage's `encoder.parquet`); `physics`:
    the run's gravity-term choice ({physics, payload}, ingest's recording.json) and `held`: the parameters
    identify's model selection held, for a URDF tree or a model with physics terms (the same model as
    identify's, not selected again) or, `chosen`, whenever identify made a model choice (its groups, or
    after a shrinkage fit what it did not estimate); `identified`: identify's fit.json, whose least-squares
    solution is the diagnosis' geometric fit where it is the same problem (`inference.reuse.identify_fit`)."""
    from pipeline.diagnose.adapters import touch_table as dtable
    from pipeline.diagnose.method import diagnose
    from pipeline.identify.model import take
    from pipeline.systems.registry import detect

    if detect(rec).SYSTEM == "scorbot-scanner":
        from pipeline.diagnose.adapters import scanner as dscan

        model, tab, _ = dscan.from_recording(rec, stream)
        if drop_records:
            tab = take(tab, ~np.isin(tab["record"], np.asarray(drop_records, int)))
        if x0 is not None and len(x0) != len(model.parameter_names()):
            x0 = None  # identify ran another model variant (joint offsets): start from the global search
        doc = diagnose(model, tab, x0=x0, settings=settings, adapter=dscan.adapter(model, tab))
        doc["dropped_records"] = sorted(int(r) for r in (drop_records or []))
        return doc
    if detect(rec).SYSTEM == "urdf":
        from pipeline.diagnose.adapters import urdf_robot as durdf

        model, tab, _ = durdf.from_recording(rec, stream, physics)
        if drop_records:
            tab = take(tab, ~np.isin(tab["record"], np.asarray(drop_records, int)))
        if x0 is not None and len(x0) != len(model.parameter_names()):
            x0 = None
        # a TreePointModel, or identify's own model choice (`held`): identify's selection stands (it is costly)
        keep = hasattr(model, "deflected") or chosen
        gf = None
        if keep and x0 is not None and identified is not None:  # identify's own fit: not solved again
            from pipeline.diagnose.inference.reuse import identify_fit

            gf = identify_fit(identified, model, tab)
        doc = diagnose(model, tab, x0=x0, settings=settings, geometry_fit=gf,
                       adapter=durdf.adapter(model, tab, held if keep and x0 is not None else None))
        doc["dropped_records"] = sorted(int(r) for r in (drop_records or []))
        if getattr(model, "residual_unit", "m") != "m":  # a camera: every *_m figure of the document is px
            doc["residual_unit"] = model.residual_unit
        return doc
    if detect(rec).SYSTEM == "delta-tracker":
        from pipeline.diagnose.adapters import delta as ddelta

        model, tab, _ = ddelta.from_recording(rec, stream)
        if drop_records:
            tab = take(tab, ~np.isin(tab["record"], np.asarray(drop_records, int)))
        if x0 is not None and len(x0) != len(model.parameter_names()):
            x0 = None  # identify ran another model variant: start from the closed-form registration
        doc = diagnose(model, tab, x0=x0, settings=settings, adapter=ddelta.adapter(model, tab))
        doc["dropped_records"] = sorted(int(r) for r in (drop_records or []))
        return doc
    model, tab, info = dtable.from_recording(rec, stream)
    if drop_records:
        tab = take(tab, ~np.isin(tab["record"], np.asarray(drop_records, int)))
    if settings.repeatability_3sigma_m is None and info.get("repeatability_3sigma_m") is not None:
        settings = replace(settings, repeatability_3sigma_m=float(info["repeatability_3sigma_m"]))
    doc = diagnose(model, tab, jig_tolerance_m=info["jig_tolerance_m"], x0=x0, settings=settings)
    doc["dropped_records"] = sorted(int(r) for r in (drop_records or []))
    if info.get("searches_without_contact", {}).get("counts"):  # /touch/miss: no contact, or a faulted search
        doc["searches_without_contact"] = info["searches_without_contact"]
    return doc


def run(run_dir: Path, params: dict) -> dict:
    """Write DIR/diagnose/diagnosis.json; return a summary for stage.json."""
    from pipeline.stages.artefacts import read_json, write_json
    from pipeline.stages.ingest import load_system, read_encoder

    run_dir = Path(run_dir)
    out = run_dir / NAME
    out.mkdir(parents=True, exist_ok=True)
    from pipeline.dynamics.stage import is_dynamics_run

    if is_dynamics_run(run_dir):  # the dynamics library on the identified torque model
        from pipeline.dynamics.stage import diagnose as diagnose_dynamics

        doc = diagnose_dynamics(run_dir, settings_of(params))
        write_json(out / "diagnosis.json", doc)
        return {"findings": [f"{f['effect']}@{f['location']}" for f in doc["findings"]],
                "unexplained": doc["unexplained"], "status": doc["status"], "family": "dynamics",
                "holdout_rms_before_Nm": doc["holdout_rms_before_m"], "holdout_rms_after_Nm": doc["holdout_rms_after_m"]}
    stream = read_encoder(run_dir)
    system, model, rec = load_system(run_dir, with_stream=stream is None)
    if system.SYSTEM not in SUPPORTED:
        doc = {"system": system.SYSTEM, "supported": False, "findings": [], "not_identifiable": [],
               "unexplained": None, "unexplained_where": [], "holdout_rms_before_m": None,
               "holdout_rms_after_m": None, "message": f"no effect library for {system.SYSTEM} yet"}
    else:
        fit_path = run_dir / "identify" / "fit.json"
        from pipeline.stages.ingest import recording_info

        x0, drop, held, chosen, fj = None, None, None, False, None
        if fit_path.is_file():
            fj = read_json(fit_path)
            x0 = np.asarray(fj["x"], float)
            drop = fj.get("rejected_records") or None
            held = tuple(n for n, r in (fj.get("reasons") or {}).items() if "model_selection" in str(r))
            sel = fj.get("model_selection") or {}
            chosen = str(sel.get("method", "")).startswith("shrinkage") or "kept_groups" in sel
            if "kept_groups" not in sel and chosen:  # shrinkage estimated every parameter: hold what it did not
                held = tuple(n for n, fr in zip(fj.get("names", []), fj.get("free", [])) if not fr)
        physics = recording_info(run_dir).get("physics")
        if physics is None and x0 is not None and any(n.endswith(PHYSICS_SUFFIXES) for n in fj.get("names", [])):
            physics = {"physics": "auto"}  # identify's default gravity terms: the same model, not selected again
        from pipeline.progress import Ticker, reporting

        tick = Ticker(NAME, log=out / PROGRESS_LOG, count=False)
        with reporting(tick):
            doc = diagnose_recording(rec, settings_of(params), x0=x0, drop_records=drop, stream=stream,
                                     physics=physics, held=held, chosen=chosen, identified=fj)
        tick.done()
        doc["supported"] = True
    write_json(out / "diagnosis.json", doc)
    return {"findings": [f"{f['effect']}@{f['location']}" for f in doc["findings"]],
            "unexplained": doc["unexplained"], "status": doc.get("status"),
            "holdout_rms_before_m": doc["holdout_rms_before_m"],
            "holdout_rms_after_m": doc["holdout_rms_after_m"],
            # what the campaign could not have seen: per effect and place the size that could hide, and what shows it
            "unseen": [{k: e[k] for k in ("effect", "location", "testable", "found", "could_have_gone_unseen", "unit",
                                          "display", "reveal")} for e in doc.get("unseen", [])]}
