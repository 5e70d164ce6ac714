"""Reading recordings: every complete record of an MCAP file, with one-line errors.

The reader streams the file from the start (`mcap.stream_reader.StreamReader`), so a file
cut short — a crash, a copy that stopped — still yields every record before the damage,
with a warning that says where the file ends.  A file that is not MCAP at all, or a message
that is not valid JSON, is a `RobocalError` naming file, channel and record.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import orjson

from mcap.records import Channel, DataEnd, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from pipeline.errors import RobocalError, where

MAGIC = b"\x89MCAP0\r\n"


def decode(data: bytes) -> object:
    """JSON body of a message: orjson when it can, the standard library for what orjson
    rejects (NaN/Infinity literals), so that such values reach the field checks."""
    try:
        return orjson.loads(data)
    except orjson.JSONDecodeError:
        return json.loads(data)


class LazyMessages(Mapping[str, list[dict]]):
    """topic -> decoded message bodies, decoded on first access (raw bytes kept)."""

    def __init__(self, path: Path) -> None:
        self._path = path
        self.raw: dict[str, list[bytes]] = {}
        self._decoded: dict[str, list[dict]] = {}

    def __getitem__(self, topic: str) -> list[dict]:
        if topic not in self._decoded:
            out = []
            for i, data in enumerate(self.raw[topic]):
                try:
                    body = decode(data)
                except (ValueError, UnicodeDecodeError) as e:
                    raise RobocalError(f"{where(self._path, topic, i)}: message is not valid JSON ({e})") from None
                if not isinstance(body, dict):
                    raise RobocalError(f"{where(self._path, topic, i)}: message is not a JSON object")
                out.append(body)
            self._decoded[topic] = out
        return self._decoded[topic]

    def __iter__(self) -> Iterator[str]:
        return iter(self.raw)

    def __len__(self) -> int:
        return len(self.raw)

    def setdefault(self, topic: str, default: list) -> list:  # type: ignore[override]
        return self.raw.setdefault(topic, default)


@dataclass
class Recording:
    """Decoded content of one MCAP file."""

    path: Path
    metadata: dict[str, dict] = field(default_factory=dict)  # name -> decoded JSON
    messages: LazyMessages = None  # type: ignore[assignment]  # topic -> message bodies (lazy)
    log_times: dict[str, list[int]] = field(default_factory=dict)  # topic -> log_time ns
    schemas: dict[str, tuple[str, str]] = field(default_factory=dict)  # topic -> (schema name, encoding)
    warnings: list[str] = field(default_factory=list)
    complete: bool = False  # the footer was reached
    profile: str = ""

    def __post_init__(self) -> None:
        if self.messages is None:
            self.messages = LazyMessages(self.path)

    def require(self, topic: str) -> list[dict]:
        if not self.messages.raw.get(topic):
            have = ", ".join(sorted(self.messages)) or "none"
            raise RobocalError(f"{where(self.path, topic)}: channel missing or empty (channels present: {have})")
        return self.messages[topic]

    def meta(self, name: str) -> dict:
        if name not in self.metadata:
            raise RobocalError(f"{self.path}: metadata record {name!r} missing (not a robocal recording?)")
        return self.metadata[name]


def read_recording(path: str | Path, topics: set[str] | None = None, skip: frozenset[str] = frozenset()) -> Recording:
    """Read every complete record (messages of `topics`, or all, less those of `skip`) and the metadata."""
    path = Path(path)
    if not path.is_file():
        raise RobocalError(f"{path}: no such file")
    with open(path, "rb") as f:
        head = f.read(len(MAGIC))
        if head != MAGIC:
            raise RobocalError(f"{path}: not an MCAP file (bad magic bytes)")
        f.seek(0)
        rec = Recording(path=path)
        channels: dict[int, Channel] = {}
        schemas: dict[int, Schema] = {}
        n = 0
        try:
            for r in StreamReader(f, validate_crcs=True).records:
                n += 1
                if isinstance(r, Message):
                    ch = channels.get(r.channel_id)
                    if ch is None:
                        raise RobocalError(f"{where(path, None, n)}: message on unknown channel id {r.channel_id}")
                    if (topics is not None and ch.topic not in topics) or ch.topic in skip:
                        continue
                    rec.messages.raw.setdefault(ch.topic, []).append(r.data)
                    rec.log_times.setdefault(ch.topic, []).append(r.log_time)
                elif isinstance(r, Channel):
                    channels[r.id] = r
                    s = schemas.get(r.schema_id)
                    rec.schemas[r.topic] = (s.name if s else "", s.encoding if s else "")
                    rec.messages.raw.setdefault(r.topic, [])
                elif isinstance(r, Schema):
                    schemas[r.id] = r
                elif isinstance(r, Metadata):
                    raw = r.metadata.get("json")
                    try:
                        rec.metadata[r.name] = json.loads(raw) if raw is not None else dict(r.metadata)
                    except ValueError:
                        raise RobocalError(f"{path}: metadata {r.name!r} is not valid JSON") from None
                elif isinstance(r, Header):
                    rec.profile = r.profile
                elif isinstance(r, (Footer,)):
                    rec.complete = True
                elif isinstance(r, DataEnd):
                    pass
        except RobocalError:
            raise
        except Exception as e:  # the mcap library raises several types on damaged input
            n_msgs = sum(len(v) for v in rec.messages.raw.values())
            rec.warnings.append(
                f"{path}: file is truncated or damaged after record {n} ({type(e).__name__}: {e}); "
                f"kept {n_msgs} complete messages")
        if not rec.complete and not rec.warnings:
            rec.warnings.append(f"{path}: file has no footer (not closed cleanly); kept every complete record")
    return rec
