"""Stage ingest: MCAP → Parquet (see docs/reference/artefacts.md).

Writes `encoder.parquet`, one `<channel>.parquet` per measurement channel, `measurements.parquet`
(the system's measurement table joined with motion context), `messages.parquet` (the recording less
the encoder stream, which later stages read instead of the MCAP) and `recording.json`.  A record
the system cannot decode does not stop ingest: the error goes to `recording.json` (`errors`)
and the validate stage fails on it with the record named.
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from pipeline.errors import RobocalError, where
from pipeline.recording.scene import SCENE_CHANNELS
from pipeline.ingest.guards import first_schema_error
from pipeline.ingest.streams import JOINT_STATE, joint_stream
from pipeline.ingest.tables import channel_table, encoder_table, measurement_table
from pipeline.ingest.temperature import temperature_stream
from pipeline.recording.reader import read_recording
from pipeline.stages.artefacts import read_json, read_table, sha256_file, write_json, write_table

NAME = "ingest"
MESSAGES = "messages.parquet"
SCENE = frozenset(SCENE_CHANNELS)  # /tf, /robot_description: for ROS / Foxglove tools, not read by the stages


def channel_file(topic: str) -> str:
    """`/touch/contact` → `touch_contact.parquet` for robocal's own channels; any other topic gets
    a file name that cannot collide with another topic's or ingest's own files, whatever it holds
    (NUL, `..`, 10⁴ bytes): its safe characters (≤ 80) and a hash of the whole topic."""
    from pipeline.recording.schemas import CHANNELS

    stem = topic.strip("/").replace("/", "_")
    if topic in CHANNELS:
        return stem + ".parquet"
    safe = re.sub(r"[^A-Za-z0-9_.]", "_", stem)[:80].lstrip(".")
    return f"{safe}-{hashlib.sha256(topic.encode('utf-8', 'surrogatepass')).hexdigest()[:12]}.parquet"


def run(run_dir: Path, params: dict) -> dict:
    out = Path(run_dir) / NAME
    path = Path(params["recording"])
    rec = read_recording(path, skip=SCENE)  # /tf, /robot_description: for ROS tools, not calibration data
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
    write_messages(out / MESSAGES, rec)
    stream = None
    if not (getattr(system, "STREAM_OPTIONAL", False) and not rec.messages.raw.get(JOINT_STATE)):
        try:
            stream = joint_stream(rec)
            write_table(out / "encoder.parquet", encoder_table(stream))
        except RobocalError as e:
            errors.append(str(e))
        except (TypeError, ValueError, OverflowError, KeyError, IndexError, AttributeError) as e:
            stream = None  # content of the wrong type: name the record the schema check finds
            errors.append(first_schema_error(rec, JOINT_STATE) or f"{where(path, JOINT_STATE)}: cannot be decoded "
                          f"({type(e).__name__}: {e})")
    n = 0
    mchan = getattr(system, "channel_for", lambda r: system.MEASUREMENT_CHANNEL)(rec)
    if not errors and mchan != JOINT_STATE and (bad := first_schema_error(rec, mchan)):
        errors.append(bad)  # checked against the schema before any numeric conversion
    if not errors:
        try:
            from pipeline.systems.registry import load_with_physics

            _, table = load_with_physics(system, rec, params.get("physics") or "auto", params.get("payload"))
            meas = measurement_table(dict(table), stream, window_s=float(params.get("context_window_s", 0.02)),
                                     temperature=temperature_stream(rec), path=path,
                                     channel=mchan)
            write_table(out / "measurements.parquet", meas)
            n = len(meas["record"])
        except RobocalError as e:
            errors.append(str(e))
        except (TypeError, ValueError, OverflowError, KeyError, IndexError, AttributeError,
                ArithmeticError) as e:  # the schema allowed it but the model cannot take it
            errors.append(f"{where(path, mchan)}: cannot be used ({type(e).__name__}: {e})")
    camp = rec.metadata.get("robocal.campaign")
    lost_at_import = [w for w in camp.get("data_lost", []) if isinstance(w, str)] if isinstance(camp, dict) else []
    doc = {
        "system": system.SYSTEM,
        "measurement_channel": mchan,
        "source": {"path": str(path), "sha256": sha256_file(path), "bytes": path.stat().st_size},
        "metadata": rec.metadata,
        "channels": channels,
        "encoder": {"samples": 0 if stream is None else len(stream),
                    "joints": [] if stream is None else list(stream.names)},
        "complete": rec.complete,
        "warnings": list(rec.warnings) + lost_at_import,  # the file's damage, and the source's before import
        "errors": errors,
        "n_measurements": n,
    }
    if params.get("physics") is not None or params.get("payload"):  # the model's gravity terms, for every stage
        doc["physics"] = {"physics": params.get("physics"), "payload": list(params.get("payload") or [])}
    write_json(out / "recording.json", doc)
    lost = bool(doc["warnings"]) or bool(errors)  # a damaged file (or bag it came from): no status pass
    return {"status": "warn" if lost else "pass", "system": system.SYSTEM, "n_measurements": n,
            "encoder_samples": doc["encoder"]["samples"],
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


def read_encoder(run_dir: Path):
    """The encoder stream ingest decoded (`encoder.parquet`) as a `JointStream`, or None when
    ingest wrote none.  Checked against `recording.json` (sample count, joint names)."""
    from pipeline.ingest.streams import JointStream

    info = recording_info(run_dir)
    p = Path(run_dir) / NAME / "encoder.parquet"
    if not p.is_file() or not info["encoder"]["samples"]:
        return None
    tab = read_table(p)
    names = tuple(info["encoder"]["joints"])
    if tab["t_ns"].size != info["encoder"]["samples"] or any(f"q_{n}" not in tab for n in names):
        raise RobocalError(f"{p}: does not match {Path(run_dir) / NAME / 'recording.json'} (re-run ingest)")
    q = np.stack([np.asarray(tab[f"q_{n}"], float) for n in names], axis=1)
    drive = [np.stack([np.asarray(tab[f"{prefix}_{n}"], float) for n in names], axis=1)
             if all(f"{prefix}_{n}" in tab for n in names) else None for prefix in ("cmd", "effort", "current", "vel")]
    return JointStream(t_ns=np.asarray(tab["t_ns"], np.int64), q=q, names=names,
                       message_index=np.asarray(tab["record"], np.int64), q_cmd=drive[0], effort=drive[1],
                       current=drive[2], velocity=drive[3])


def write_messages(path: Path, rec) -> None:
    """`messages.parquet`: the recording less the encoder stream, as it was read — every other
    message's raw JSON body (`topic`, `log_time_ns`, `body` binary, in file order per channel) and,
    in the Parquet schema metadata `robocal.recording`, what else the reader found (channel order,
    schemas, metadata records, complete, warnings, profile).  Later stages rebuild the `Recording`
    from it (`load_system`) instead of decompressing the whole MCAP again."""
    topics = [t for t in rec.messages.raw if t != JOINT_STATE]
    rows = [(t, lt, b) for t in topics for lt, b in zip(rec.log_times.get(t, []), rec.messages.raw[t])]
    doc = {"topics": list(rec.messages.raw), "schemas": rec.schemas, "encodings": rec.encodings, "metadata": rec.metadata,
           "complete": rec.complete, "warnings": rec.warnings, "profile": rec.profile}
    table = pa.table({"topic": pa.array([r[0] for r in rows], pa.string()),
                      "log_time_ns": pa.array([r[1] for r in rows], pa.int64()),
                      "body": pa.array([r[2] for r in rows], pa.binary())},
                     metadata={"robocal.recording": json.dumps(doc)})
    pq.write_table(table, path, compression="zstd")


def read_messages(run_dir: Path, info: dict):
    """The `Recording` (without the encoder stream's messages) that ingest kept in
    `messages.parquet`, or None when the run predates it."""
    from pipeline.recording.reader import Recording

    p = Path(run_dir) / NAME / MESSAGES
    if not p.is_file():
        return None
    try:
        table = pq.read_table(p)
        doc = json.loads(table.schema.metadata[b"robocal.recording"])
    except (pa.ArrowException, OSError, KeyError, TypeError, ValueError) as e:
        raise RobocalError(f"{p}: unreadable ({type(e).__name__}: {e}); re-run ingest") from None
    counts = {v["values"]: v["counts"] for v in pc.value_counts(table.column("topic")).to_pylist()}
    for topic, ch in info.get("channels", {}).items():
        if topic != JOINT_STATE and counts.get(topic, 0) != ch["messages"]:
            raise RobocalError(f"{p}: {counts.get(topic, 0)} messages on {topic}, "
                               f"{Path(run_dir) / NAME / 'recording.json'} says {ch['messages']} (re-run ingest)")
    rec = Recording(path=Path(info["source"]["path"]), metadata=doc["metadata"],
                    schemas={t: tuple(v) for t, v in doc["schemas"].items()}, warnings=doc["warnings"],
                    encodings=doc.get("encodings", {}),
                    complete=doc["complete"], profile=doc["profile"])
    for t in doc["topics"]:
        rec.messages.raw[t] = []
    for t, lt, b in zip(*(table.column(c).to_pylist() for c in ("topic", "log_time_ns", "body"))):
        rec.messages.raw[t].append(b)
        rec.log_times.setdefault(t, []).append(lt)
    return rec


def load_system(run_dir: Path, with_stream: bool = False):
    """(system module, measurement model, recording) of a run: the model comes from the
    recording's own metadata via the system's `load`.  The encoder stream's messages are left
    out unless `with_stream` (ingest decoded them into `encoder.parquet`: `read_encoder`); the
    rest comes from ingest's `messages.parquet` (`read_messages`), or from the MCAP again."""
    from pipeline.systems.registry import SYSTEMS

    info = recording_info(run_dir)
    rec = None if with_stream else read_messages(run_dir, info)
    if rec is None:
        rec = read_recording(info["source"]["path"], skip=SCENE if with_stream else SCENE | {JOINT_STATE})
    system = SYSTEMS[info["system"]]
    from pipeline.systems.registry import load_with_physics

    phys = info.get("physics") or {}
    model, _ = load_with_physics(system, rec, phys.get("physics") or "auto", phys.get("payload"))
    return system, model, rec
