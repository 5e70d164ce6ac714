"""The dynamics model family inside robocal's stages (imperative shell): what identify, observe and
evaluate do for a recording whose campaign measures ``effort``.

identify writes, under DIR/identify/: ``fit.json`` (the model choice, every candidate's held-out RMS, θ with
names and units, base parameters with σ, condition number, training and held-out RMS per fitted joint),
``dynamics.json`` (what `predict` needs), ``torques.parquet`` (per sample: measured, fitted and held-out
predicted torque per fitted joint), ``model.urdf`` (the physically consistent inertials) and
``dynamics.yaml`` (friction, armature and the drives' effort → torque declaration).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError
from pipeline.recording.schemas import META_CAMPAIGN, META_URDF

DYNAMICS_JSON = "dynamics.json"


def is_dynamics_run(run_dir: Path) -> bool:
    """The run's recording measures efforts (campaign ``measure: effort``)."""
    from pipeline.stages.ingest import recording_info

    try:
        meta = recording_info(run_dir).get("metadata", {})
    except RobocalError:
        return False
    camp = meta.get(META_CAMPAIGN)
    return isinstance(camp, dict) and camp.get("measure") == "effort"


def model_of_metadata(meta: dict, path: str):
    """The `DynamicsModel` of a recording's metadata records."""
    from pipeline.dynamics import effort as E
    from pipeline.models import urdf
    from pipeline.systems.urdf_dynamics import DynamicsModel

    u = meta.get(META_URDF) or {}
    desc = urdf.parse(u["urdf"], u["root"], u["tip"], source=f"{path}: metadata robocal.urdf")
    doc = E.check((meta.get(META_CAMPAIGN) or {}).get("effort"), desc.joint_names, f"{path}: metadata robocal.campaign")
    from pipeline.systems.urdf_dynamics import positions_doc

    pos = positions_doc((meta.get(META_CAMPAIGN) or {}).get("positions"), desc.joint_names, path)
    return DynamicsModel(u["urdf"], u["root"], u["tip"], tuple(desc.joint_names), doc, path, positions=pos)


def _data(model, table: dict, where_: str, model_rate: bool = False):
    """The recording's `Data`; `model_rate`: decimated to at most `signals.MODEL_RATE_HZ` (what identify and
    diagnose work on; evaluate scores every recorded sample)."""
    from pipeline.dynamics import effort as E
    from pipeline.dynamics import signals
    from pipeline.dynamics.identify import Data

    E.require_units(model.effort, where_)
    t = (np.asarray(table["timestamp_ns"], np.int64) - int(table["timestamp_ns"][0])) * 1e-9
    q, tau = np.asarray(table["joint_positions"], float), np.asarray(table["joint_torques"], float)
    k = signals.decimation_factor(t) if model_rate else 1
    t, q, tau = signals.decimate(t, q, tau, k)
    return Data(t=t, q=q, tau=tau, fit=model.fit_mask, decimation=k)


def _progress(line: str) -> None:
    import sys

    print(f"identify: {line}", file=sys.stderr, flush=True)


def identify(run_dir: Path, params: dict) -> dict:
    """The identify stage of a dynamics recording."""
    from pipeline.dynamics import identify as I
    from pipeline.dynamics import report_files as R
    from pipeline.stages.artefacts import write_json, write_table
    from pipeline.stages.ingest import read_measurements, recording_info

    run_dir = Path(run_dir)
    out = run_dir / "identify"
    info = recording_info(run_dir)
    path = info["source"]["path"]
    model = model_of_metadata(info["metadata"], path)
    table = read_measurements(run_dir)
    data = _data(model, table, path, model_rate=True)
    rb = model.rigid_body()
    fit = I.identify(rb, data, I.candidates_for(data, model.motors), folds=int(params.get("folds", 5)),
                     progress=_progress)
    out.mkdir(parents=True, exist_ok=True)
    doc = R.fit_document(rb, model, fit, data)
    write_json(out / "fit.json", doc)
    write_json(out / DYNAMICS_JSON, R.predictor_document(model, fit))
    write_table(out / "torques.parquet", R.torque_table(rb, fit, data, model))
    (out / "model.urdf").write_text(R.identified_urdf(model, rb, fit))
    (out / "dynamics.yaml").write_text(R.sidecar_yaml(model, fit))
    keys = ("system", "family", "n_measurements", "n_parameters", "n_identifiable", "condition_number",
            "rms_after_Nm", "holdout_rms_Nm", "holdout_kind", "model_choice_label", "warnings", "status")
    return {k: doc[k] for k in keys if k in doc}


def observe(run_dir: Path) -> dict:
    """Singular values and condition number of the base regressor, base-parameter correlations."""
    from pipeline.stages.artefacts import read_json, write_json

    fit = read_json(Path(run_dir) / "identify" / "fit.json")
    cov = np.asarray(fit["base_cov"], float)
    d = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    corr = cov / np.outer(d, d)
    iu = np.triu_indices_from(corr, 1)
    worst = np.argsort(-np.abs(corr[iu]))[:10]
    doc = {"family": "dynamics", "condition_number": fit["condition_number"],
           "singular_values": fit["singular_values"], "n_identifiable": fit["n_identifiable"],
           "most_correlated": [{"a": fit["base_names"][iu[0][k]], "b": fit["base_names"][iu[1][k]],
                                "correlation": float(corr[iu][k])} for k in worst]}
    write_json(Path(run_dir) / "observe" / "observe.json", doc)
    return {"status": "pass", "condition_number": fit["condition_number"], "n_identifiable": fit["n_identifiable"]}


def diagnose(run_dir: Path, settings) -> dict:
    """The diagnose stage of a dynamics recording: the document of DIR/diagnose/diagnosis.json (the dynamics
    library on the identified model: `pipeline.diagnose.adapters.dynamics_diagnosis`), `settings` the
    diagnosis' (`pipeline.diagnose.method.Settings`)."""
    from pipeline.diagnose.adapters.dynamics_diagnosis import diagnose as run_diagnosis
    from pipeline.dynamics import identify as I
    from pipeline.stages.artefacts import read_json
    from pipeline.stages.ingest import read_measurements, recording_info

    run_dir = Path(run_dir)
    info = recording_info(run_dir)
    model = model_of_metadata(info["metadata"], info["source"]["path"])
    data = _data(model, read_measurements(run_dir), info["source"]["path"], model_rate=True)
    rb = model.rigid_body()
    fit = I.from_document(read_json(run_dir / "identify" / DYNAMICS_JSON))
    fit.base = I.structural_base(rb, model.fit_mask, fit.choice.terms)
    cons = (read_json(run_dir / "identify" / "fit.json").get("consistent") or {}).get("theta")
    if cons is not None:  # the physically consistent inertials: the diagnosis' first-order gains
        from pipeline.dynamics.solve import Solution

        fit.consistent = Solution(np.asarray(cons, float), np.zeros(0), np.zeros(0), np.zeros(0), "consistent")
    say = lambda line: print(f"diagnose: {line}", file=sys.stderr, flush=True)  # noqa: E731
    return run_diagnosis(rb, data, fit, settings, progress=say)


def is_dynamics_recording(rec) -> bool:
    """The recording's campaign measures efforts (``measure: effort``)."""
    camp = rec.meta(META_CAMPAIGN)
    return isinstance(camp, dict) and camp.get("measure") == "effort"


def diagnose_recording(rec, settings, progress=None) -> dict:
    """Identify a dynamics recording (the held-out model choice) and diagnose it: the diagnosis document."""
    from pipeline.diagnose.adapters.dynamics_diagnosis import diagnose as run_diagnosis
    from pipeline.dynamics import identify as I
    from pipeline.systems.urdf_dynamics import load

    model, table = load(rec)
    data = _data(model, table, str(rec.path), model_rate=True)
    rb = model.rigid_body()
    fit = I.identify(rb, data, I.candidates_for(data, model.motors), progress=progress)
    return run_diagnosis(rb, data, fit, settings, progress=progress)


def not_applicable(stage: str) -> dict:
    return {"status": "pass", "applicable": False,
            "note": f"{stage}: not part of a dynamics identification (its held-out torque error is identify's)"}


def evaluate(run_dir: Path, recordings: list[Path]) -> list[dict]:
    """Held-out torque RMS per fitted joint and pooled of the run's model on each recording, no refit."""
    from pipeline.dynamics import identify as I
    from pipeline.recording.reader import read_recording
    from pipeline.stages.artefacts import read_json
    from pipeline.stages.ingest import recording_info
    from pipeline.systems.urdf_dynamics import load

    pred = read_json(Path(run_dir) / "identify" / DYNAMICS_JSON)
    info = recording_info(run_dir)
    trained = model_of_metadata(info["metadata"], info["source"]["path"])
    rb = trained.rigid_body()
    fit = I.from_document(pred)
    results = []
    for p in recordings:
        model, table = load(read_recording(p))
        if list(model.joints) != list(trained.joints):
            raise RobocalError(f"{p}: joints {list(model.joints)} differ from the calibrated model's "
                               f"{list(trained.joints)}")
        data = _data(model, table, str(p))
        mask = np.isin(trained.joints, pred["fit_joints"])
        tau_hat = I.predict(rb, fit, data.t, data.q, mask)
        r = tau_hat - data.tau[:, mask]
        joints = [j for j in trained.joints if j in pred["fit_joints"]]
        nominal = I.nominal_torques(rb, data, mask)
        rn = nominal - data.tau[:, mask]
        results.append({"path": str(p), "measure": "effort", "n": int(r.shape[0]),
                        "rms_joint_Nm": dict(zip(joints, np.sqrt(np.mean(r**2, 0)).tolist())),
                        "rms_pooled_Nm": float(np.sqrt(np.mean(r**2))),
                        "nominal_rms_joint_Nm": dict(zip(joints, np.sqrt(np.mean(rn**2, 0)).tolist())),
                        "nominal_rms_pooled_Nm": float(np.sqrt(np.mean(rn**2))),
                        "t_s": data.t, "measured": data.tau[:, mask], "predicted": tau_hat, "joints": joints})
    return results
