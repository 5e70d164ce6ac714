"""One row of the reprocess dataset per recording: what a task returns (run on a Dask worker, a
pool process or in-process) and the Arrow schema every part of the dataset is written with."""

from __future__ import annotations

import os
import socket
import time
from pathlib import Path

import pyarrow as pa

from pipeline import __version__

FIGURES = ("system", "n_measurements", "n_used", "rms_before_m", "rms_after_m", "holdout_rms_m",
           "n_identifiable", "n_parameters", "predicted_point_sigma_rms_m", "residual_unit")
PARAMETER = pa.struct([("name", pa.string()), ("unit", pa.string()), ("nominal", pa.float64()),
                       ("estimate", pa.float64()), ("std", pa.float64()), ("identifiable", pa.bool_())])
SCHEMA = pa.schema([
    ("recording", pa.string()),            # path relative to the archive (POSIX)
    ("path", pa.string()),                 # absolute path as read
    ("input_sha256", pa.string()),
    ("input_bytes", pa.int64()),
    ("robot_id", pa.string()),
    ("robot_id_source", pa.string()),      # "recording" (campaign metadata) or "override"
    ("campaign_start_ns", pa.int64()),     # first measurement, ns since the Unix epoch
    ("campaign_end_ns", pa.int64()),
    ("system", pa.string()),
    ("status", pa.string()),               # pass / warn / fail / error / crash / lost
    ("error", pa.string()),                # the one-line reason when status is fail/error/crash/lost
    ("n_measurements", pa.int64()),
    ("n_used", pa.int64()),
    ("rms_before_m", pa.float64()),
    ("rms_after_m", pa.float64()),
    ("holdout_rms_m", pa.float64()),
    ("n_identifiable", pa.int64()),
    ("n_parameters", pa.int64()),
    ("predicted_point_sigma_rms_m", pa.float64()),
    ("sigma_m", pa.float64()),
    ("residual_unit", pa.string()),        # px for a camera run (its *_m residual figures are px); null: m
    ("residual_dof", pa.int64()),          # residuals used − identified parameters (σ's degrees of freedom)
    ("warnings", pa.list_(pa.string())),
    ("parameters", pa.list_(PARAMETER)),
    ("expected", pa.string()),
    ("regressions", pa.list_(pa.string())),
    ("ok", pa.bool_()),
    ("robocal_version", pa.string()),
    ("code_version", pa.string()),         # fingerprint of robocal's sources (the stage cache's)
    ("config", pa.string()),               # stages and overrides the row was computed with
    ("run_dir", pa.string()),
    ("elapsed_s", pa.float64()),           # task wall time on the worker
    ("worker", pa.string()),               # host:pid that ran it
])
FAILED = ("fail", "error", "crash", "lost")


def code_version() -> str:
    from pipeline.stages.runner import code_fingerprint

    return code_fingerprint()[:16]


def empty_row(rec: str, path: str, sha: str, nbytes: int, config: str, run_dir: str) -> dict:
    row = {f.name: None for f in SCHEMA}
    row.update(recording=rec, path=path, input_sha256=sha, input_bytes=nbytes, robocal_version=__version__,
               code_version=code_version(), config=config, run_dir=run_dir, warnings=[], parameters=[],
               regressions=[], ok=False, worker=f"{socket.gethostname()}:{os.getpid()}")
    return row


def _campaign_meta(run_dir: Path, recording: Path) -> dict:
    """The recording's campaign metadata: from ingest's recording.json, else read from the MCAP."""
    from pipeline.recording.schemas import META_CAMPAIGN
    from pipeline.stages.artefacts import read_json

    p = run_dir / "ingest" / "recording.json"
    try:
        if p.is_file():
            return dict(read_json(p).get("metadata", {}).get(META_CAMPAIGN) or {})
        from pipeline.recording.reader import read_recording

        return dict(read_recording(recording, topics=set()).metadata.get(META_CAMPAIGN) or {})
    except Exception:  # noqa: BLE001 — an unreadable file has no identity; its error is the row's
        return {}


def _campaign_time(run_dir: Path) -> tuple[int | None, int | None]:
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    p = run_dir / "ingest" / "measurements.parquet"
    try:
        t = pq.read_table(p, columns=["timestamp_ns"]).column(0)
        mm = pc.min_max(t).as_py()
        return mm["min"], mm["max"]
    except Exception:  # noqa: BLE001 — no measurements table: no campaign time
        return None, None


def fill_from_run(row: dict, run_dir: Path, recording: Path, robot_id: str | None) -> None:
    """Figures, parameters with σ, robot identity and campaign time from a run folder."""
    from pipeline.stages.artefacts import read_json

    res = run_dir / "results.json"
    if res.is_file():
        doc = read_json(res)
        s = doc.get("summary", {})
        row.update({k: s.get(k) for k in FIGURES})
        row["status"] = s.get("status")
        row["warnings"] = [str(w) for w in doc.get("warnings", [])]
    fit = run_dir / "identify" / "fit.json"
    if fit.is_file() and row["status"] != "fail":
        f = read_json(fit)
        row["sigma_m"] = f.get("sigma_m")
        if f.get("n_used") is not None and f.get("n_identifiable") is not None:
            row["residual_dof"] = int(f["n_used"]) * int(f.get("residual_dim", 1)) - int(f["n_identifiable"])
        row["parameters"] = [{k: p.get(k) for k in PARAMETER.names} for p in f.get("parameters", [])]
    meta = _campaign_meta(run_dir, recording)
    if robot_id:
        row["robot_id"], row["robot_id_source"] = robot_id, "override"
    elif meta.get("robot_id"):
        row["robot_id"], row["robot_id_source"] = str(meta["robot_id"]), "recording"
    row["system"] = row["system"] or meta.get("system")
    row["campaign_start_ns"], row["campaign_end_ns"] = _campaign_time(run_dir)


def reprocess_one(path: str, rel: str, sha: str | None, nbytes: int | None, run_dir: str,
                  stages: list[str] | None, robot_id: str | None, config: str) -> dict:
    """The task: run the pipeline on one recording and return its row (never raises for the
    recording's own faults: a failure is the row's `status` and `error`).  `sha` None: the input hash
    is computed here, of the file as this task reads it."""
    from pipeline.errors import RobocalError
    from pipeline.stages.artefacts import sha256_file
    from pipeline.stages.runner import StageFailed, run_pipeline

    t0 = time.perf_counter()
    rec, out = Path(path), Path(run_dir)
    if sha is None:
        try:
            sha, nbytes = sha256_file(rec), rec.stat().st_size
        except OSError as e:  # unreadable: the row says so
            row = empty_row(rel, str(rec), "", 0, config, run_dir)
            row.update(status="error", error=f"{rec}: cannot be read ({e.strerror})")
            row["elapsed_s"] = time.perf_counter() - t0
            return gate(row, rec)
    row = empty_row(rel, str(rec.resolve()), sha, nbytes, config, run_dir)
    error = None
    try:
        run_pipeline(rec, out, stages=stages)
    except StageFailed as e:
        row["status"], error = "fail", str(e)
    except RobocalError as e:
        row["status"], error = "error", str(e)
    except Exception as e:  # noqa: BLE001 — a crash on one recording must not hide the others
        row["status"], error = "crash", f"{type(e).__name__}: {e}"
    status = row["status"]
    fill_from_run(row, out, rec, robot_id)
    if error:
        row["status"], row["error"] = status, error.splitlines()[0] if error else error
    gate(row, rec)
    row["elapsed_s"] = time.perf_counter() - t0
    return row


def gate(row: dict, recording: Path) -> dict:
    """The regression gate: the row's figures against `<stem>.expected.json` beside the recording (re-run
    on rows kept by a resume, since the expected figures may have changed); sets `expected`,
    `regressions` and `ok`."""
    from pipeline.stages.artefacts import read_json
    from pipeline.stages.reprocess import compare_expected

    rec = Path(recording)
    exp = rec.with_name(rec.name.removesuffix(".mcap") + ".expected.json")
    row["expected"], row["regressions"] = None, []
    if exp.is_file() and row["status"] != "lost":
        summary = {k: row[k] for k in (*FIGURES, "status")}
        try:
            row["regressions"] = compare_expected(summary, read_json(exp))
        except (ValueError, TypeError, AttributeError, RecursionError) as e:
            row["regressions"] = [f"{exp.name}: unreadable expected figures ({str(e)[:200]})"]
        row["expected"] = exp.name
    row["ok"] = row["status"] not in FAILED and not row["regressions"]
    return row


def lost_row(path: str, rel: str, sha: str, nbytes: int, run_dir: str, config: str, reason: str) -> dict:
    """The row of a task whose worker died (after Dask's retries) or that could not be run."""
    row = empty_row(rel, path, sha, nbytes, config, run_dir)
    row.update(status="lost", error=reason, worker=None)
    return row
