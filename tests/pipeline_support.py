"""Test helpers of the pipeline/validate/plan tests: small recordings cut from the bundled
one (real MCAP written with RecordingWriter), and one pipeline run per test session."""

from __future__ import annotations

import copy
from pathlib import Path

from pipeline.recording.reader import read_recording
from pipeline.recording.writer import RecordingWriter

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "recordings" / "arc-welder-touch.mcap"
JS, TC = "/robot/joint_state", "/touch/contact"

_cache: dict = {}


def base_campaign(n_contacts: int = 40) -> tuple[dict, list[dict], list[dict]]:
    """(metadata, joint_state messages, contact messages) of the bundled recording's first
    `n_contacts` contacts and the encoder stream up to one second after the last."""
    if n_contacts not in _cache:
        rec = read_recording(BUNDLED)
        contacts = rec.messages[TC][:n_contacts]
        t_end = contacts[-1]["timestamp_ns"] + 1_000_000_000
        js = [m for m in rec.messages[JS] if m["timestamp_ns"] <= t_end]
        _cache[n_contacts] = (dict(rec.metadata), js, contacts)
    meta, js, contacts = _cache[n_contacts]
    return copy.deepcopy(meta), copy.deepcopy(js), copy.deepcopy(contacts)


def write(path: Path, meta: dict, js: list[dict], contacts: list[dict], raw: dict[int, bytes] | None = None,
          stream_encoding: str = "protobuf") -> Path:
    """Write a recording; `raw` replaces the encoded body of contact i (e.g. to put a NaN
    literal in, which the JSON encoder refuses); `stream_encoding="json"` writes the encoder
    stream as archived recordings have it."""
    raw = raw or {}
    msgs = [(JS, m, None) for m in js] + [(TC, m, raw.get(i)) for i, m in enumerate(contacts)]
    msgs.sort(key=lambda x: x[1].get("timestamp_ns", 0) if isinstance(x[1].get("timestamp_ns"), int) else 0)
    with RecordingWriter(path, stream_encoding=stream_encoding) as w:
        for k, v in meta.items():
            w.metadata(k, v)
        for topic, m, body in msgs:
            if body is None:
                w.write(topic, m, log_time_ns=m.get("timestamp_ns", 0) if isinstance(m.get("timestamp_ns"), int) else 0)
            else:  # raw bytes through the underlying mcap writer
                cid = w.channel(topic)
                t = int(m["timestamp_ns"])
                w._w.add_message(cid, log_time=t, data=body, publish_time=t, sequence=0)
    return path
