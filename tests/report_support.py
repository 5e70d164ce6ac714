"""Test helper: a run directory that follows docs/reference/artefacts.md exactly, built from a real
simulated arc-welder recording with the existing identification functions.

Used by the report/rerun tests until (and as a cross-check after) the pipeline stages land.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline import __version__
from pipeline.identify.least_squares import FitOptions, cross_validate, fit, point_accuracy
from pipeline.ingest.context import motion_context
from pipeline.ingest.streams import joint_stream
from pipeline.recording.reader import read_recording
from pipeline.systems.registry import detect


def _stage(d: Path, name: str, params: dict, inputs: list[str]) -> None:
    d.mkdir(parents=True, exist_ok=True)
    (d / "stage.json").write_text(json.dumps({
        "stage": name, "key": hashlib.sha256(f"{name}{params}".encode()).hexdigest()[:16], "params": params,
        "inputs": inputs, "elapsed_s": 0.01, "robocal_version": __version__}))


def make_run(recording: Path, out: Path, *, diagnosis: bool = False) -> Path:
    """Write DIR/{ingest,validate,identify,observe}[/diagnose] artefacts for `recording`."""
    rec = read_recording(recording)
    system = detect(rec)
    model, table = system.load(rec)
    stream = joint_stream(rec)
    names = list(stream.names)
    sha = hashlib.sha256(recording.read_bytes()).hexdigest()

    ing = out / "ingest"
    _stage(ing, "ingest", {}, [str(recording)])
    pq.write_table(pa.table({"t_ns": stream.t_ns, **{f"q_{n}": stream.q[:, j] for j, n in enumerate(names)}}),
                   ing / "encoder.parquet")
    ctx = motion_context(stream, table["timestamp_ns"])
    meas = {"record": table["record"], "timestamp_ns": table["timestamp_ns"],
            **{f"q_{nm}": table["joint_positions"][:, j] for j, nm in enumerate(names)},
            "axis": np.array(["xyz"[a] for a in table["axis"]]), "coordinate": table["coordinate"],
            "face": table["face"].astype(str),
            **{f"v_{nm}": ctx["joint_velocity"][:, j] for j, nm in enumerate(names)},
            **{f"dir_{nm}": ctx["last_motion_sign"][:, j].astype(np.int8) for j, nm in enumerate(names)},
            "time_since_start_s": ctx["time_since_start_s"]}
    pq.write_table(pa.table(meas), ing / "measurements.parquet")
    (ing / "recording.json").write_text(json.dumps({
        "system": system.SYSTEM, "metadata": rec.metadata, "warnings": rec.warnings, "sha256": sha,
        "path": str(recording)}))

    val = out / "validate"
    _stage(val, "validate", {"outlier_mad": 5.0}, ["ingest"])
    (val / "validate.json").write_text(json.dumps({"checks": [
        {"name": "schema", "status": "pass", "message": "every message conforms", "records": []},
        {"name": "monotonic_time", "status": "pass", "message": "time strictly increasing", "records": []},
        {"name": "joint_limits", "status": "warn", "message": "2 samples within 1° of a limit", "records": [3, 7]},
    ]}))

    opts = FitOptions()
    f = fit(model, table, opts)
    hold = cross_validate(model, table, k=5, seed=0, options=opts)
    idn = out / "identify"
    _stage(idn, "identify", {"loss": "linear", "folds": 5}, ["ingest", "validate"])
    (idn / "fit.json").write_text(json.dumps({
        "names": f.names, "units": f.units, "nominal": f.nominal.tolist(), "x": f.x.tolist(),
        "std": f.std.tolist(), "free": f.free.tolist(),
        "reasons": {f.names[i]: r for i, r in f.identifiability.reasons.items()},
        "sigma_m": f.sigma, "cov": f.cov.tolist(), "rejected_records": [], "loss": "linear"}))
    res = {"record": table["record"], "timestamp_ns": table["timestamp_ns"], "group": table["face"].astype(str)}
    for k in range(model.residual_dim):
        res[f"before_{k}"] = f.residuals_before[:, k]
        res[f"after_{k}"] = f.residuals_after[:, k]
        res[f"holdout_{k}"] = hold[:, k]
    pq.write_table(pa.table(res), idn / "residuals.parquet")
    (idn / "history.json").write_text(json.dumps(f.history))
    (idn / "model.json").write_text(json.dumps(model.describe(f.x)))

    obs = out / "observe"
    _stage(obs, "observe", {}, ["identify"])
    J = model.jacobian(f.x, table).reshape(-1, len(f.names))[:, f.free]
    Js = J / np.linalg.norm(J, axis=0)
    s = np.linalg.svd(Js, compute_uv=False)
    m = Js.shape[0]
    sd = np.sqrt(np.clip(np.diag(f.cov), 1e-300, None))
    corr = f.cov / np.outer(sd, sd)
    (obs / "observe.json").write_text(json.dumps({
        "singular_values": s.tolist(), "O1": float(np.prod(s) ** (1 / s.size) / np.sqrt(m)),
        "O2": float(s[-1] / s[0]), "O3": float(s[-1]), "O4": float(s[-1] ** 2 / s[0]),
        "O5": float(1 / np.sum(1 / s)), "identifiable": [nm for nm, fr in zip(f.names, f.free) if fr],
        "dependencies": {f.names[i]: r for i, r in f.identifiability.reasons.items()},
        "correlation": corr.tolist(), "predicted_point_sigma_m": point_accuracy(model, f, table).tolist()}))

    if diagnosis:
        dg = out / "diagnose"
        _stage(dg, "diagnose", {}, ["identify"])
        t = meas["time_since_start_s"]
        r = f.residuals_after[:, 0]
        (dg / "diagnosis.json").write_text(json.dumps({"findings": [{
            "name": "thermal drift", "variable": "time_since_start_s", "p_value": 0.003,
            "rms_before_m": float(np.sqrt(np.mean(r ** 2))), "rms_after_m": float(np.sqrt(np.mean(r ** 2)) * 0.8),
            "message": "residuals grow with time since start",
            "plot": {"kind": "added_variable", "x_label": "time since start (s)", "x": t.tolist(),
                     "before_m": r.tolist(), "after_m": (0.8 * r).tolist()}}]}))
    return out


# ----- one real pipeline run per test session (ingest → … → observe → report) ---------------
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402

import pytest  # noqa: E402

_RUN: dict = {}


@pytest.fixture(scope="session")
def report_run(tmp_path_factory) -> Path:
    """A run folder produced by `robocal run` (real stages, report included) on a freshly simulated
    40-contact arc-welder recording."""
    if "dir" not in _RUN:
        tmp = tmp_path_factory.mktemp("report")
        rec = tmp / "arc40.mcap"
        robocal = str(Path(sys.executable).parent / "robocal")
        subprocess.run([robocal, "simulate", "arc-welder", "--out", str(rec), "--contacts", "40", "--seed", "5"],
                       check=True, capture_output=True, timeout=300)
        from pipeline.stages.runner import run_pipeline

        run_pipeline(rec, tmp / "run")
        _RUN["dir"] = tmp / "run"
        _RUN["recording"] = rec
    return _RUN["dir"]


def copy_run(src: Path, dst: Path) -> Path:
    """A copy of a run folder (to add artefacts without touching the shared one)."""
    shutil.copytree(src, dst)
    return dst
