"""Stage ingest: MCAP → Parquet (see docs/pipeline-artefacts.md).

Writes `encoder.parquet`, one `<channel>.parquet` per measurement channel, `measurements.parquet`
(the system's measurement table joined with motion context) and `recording.json`.  A record
the system cannot decode does not stop ingest: the error goes to `recording.json` (`errors`)
and the validate stage fails on it with the record named.
"""

from __future__ import annotations

from pathlib import Path

import pyarrow.parquet as pq

from pipeline.errors import RobocalError
from pipeline.ingest.streams import JOINT_STATE, joint_stream
from pipeline.ingest.tables import channel_table, encoder_table, measurement_table
from pipeline.ingest.temperature import temperature_stream
from pipeline.recording.reader import read_recording
from pipeline.stages.artefacts import read_json, read_table, sha256_file, write_json, write_table

NAME = "ingest"


def channel_file(topic: str) -> str:
    """`/touch/contact` → `touch_contact.parquet`."""
    return topic.strip("/").replace("/", "_") + ".parquet"


def run(run_dir: Path, params: dict) -> dict:
    out = Path(run_dir) / NAME
    path = Path(params["recording"])
    rec = read_recording(path)
    from pipeline.systems.registry import detect

    system = detect(rec)
    errors: list[str] = []
    channels = {}
    for topic in sorted(rec.messages.raw if hasattr(rec.messages, "raw") else rec.messages):
        if topic == JOINT_STATE:
            continue
        try:
            msgs = rec.messages[topic]
        except RobocalError as e:
            errors.append(str(e))
            continue
        if not msgs:
            continue
        pq.write_table(channel_table(msgs, rec.log_times.get(topic)), out / channel_file(topic), compression="zstd")
        channels[topic] = {"file": channel_file(topic), "messages": len(msgs)}
    stream = None
    try:
        stream = joint_stream(rec)
        write_table(out / "encoder.parquet", encoder_table(stream))
    except RobocalError as e:
        errors.append(str(e))
    n = 0
    if not errors:
        try:
            _, table = system.load(rec)
            meas = measurement_table(dict(table), stream, window_s=float(params.get("context_window_s", 0.02)),
                                     temperature=temperature_stream(rec), path=path,
                                     channel=system.MEASUREMENT_CHANNEL)
            write_table(out / "measurements.parquet", meas)
            n = len(meas["record"])
        except RobocalError as e:
            errors.append(str(e))
    doc = {
        "system": system.SYSTEM,
        "measurement_channel": system.MEASUREMENT_CHANNEL,
        "source": {"path": str(path), "sha256": sha256_file(path), "bytes": path.stat().st_size},
        "metadata": rec.metadata,
        "channels": channels,
        "encoder": {"samples": 0 if stream is None else len(stream),
                    "joints": [] if stream is None else list(stream.names)},
        "complete": rec.complete,
        "warnings": list(rec.warnings),
        "errors": errors,
        "n_measurements": n,
    }
    write_json(out / "recording.json", doc)
    return {"system": system.SYSTEM, "n_measurements": n, "encoder_samples": doc["encoder"]["samples"],
            "channels": channels, "source": doc["source"], "warnings": doc["warnings"], "errors": errors}


# ----- readers for later stages ----------------------------------------------------------
def recording_info(run_dir: Path) -> dict:
    p = Path(run_dir) / NAME / "recording.json"
    if not p.is_file():
        raise RobocalError(f"{run_dir}: no ingest artefacts (run `robocal ingest` first)")
    return read_json(p)


def read_measurements(run_dir: Path) -> dict:
    """measurements.parquet as a table (k-vector columns restored)."""
    p = Path(run_dir) / NAME / "measurements.parquet"
    if not p.is_file():
        raise RobocalError(f"{p}: missing (ingest could not build the measurement table; see validate)")
    return read_table(p)


def load_system(run_dir: Path):
    """(system module, measurement model, recording) of a run: the model comes from the
    recording's own metadata via the system's `load`."""
    from pipeline.systems.registry import SYSTEMS

    info = recording_info(run_dir)
    rec = read_recording(info["source"]["path"])
    system = SYSTEMS[info["system"]]
    model, _ = system.load(rec)
    return system, model, rec
