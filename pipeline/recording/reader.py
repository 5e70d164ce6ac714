"""Reading recordings: every complete record of an MCAP file, with one-line errors.

The reader streams the file from the start (`mcap.stream_reader.StreamReader`), so a file
cut short — a crash, a copy that stopped — still yields every record before the damage,
with a warning that says where the file ends.  A file that is not MCAP at all, or a message
that is not valid JSON, is a `RobocalError` naming file, channel and record.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import orjson

from mcap.records import Channel, Header, Metadata, Schema

from pipeline.errors import RobocalError, where
from pipeline.recording import framing as F
from pipeline.recording.framing import MAGIC, ReadLimits


def decode(data: bytes) -> object:
    """JSON body of a message: orjson when it can, the standard library for what orjson
    rejects (NaN/Infinity literals), so that such values reach the field checks."""
    try:
        return orjson.loads(data)
    except orjson.JSONDecodeError:
        try:
            return json.loads(data)
        except RecursionError:
            raise ValueError("JSON nested too deeply") from None


class LazyMessages(Mapping[str, list[dict]]):
    """topic -> decoded message bodies, decoded on first access (raw bytes kept)."""

    def __init__(self, path: Path, encodings: dict[str, str] | None = None) -> None:
        self._path = path
        self.raw: dict[str, list[bytes]] = {}
        self._decoded: dict[str, list[dict]] = {}
        self._encodings = {} if encodings is None else encodings  # topic -> message encoding

    def __getitem__(self, topic: str) -> list[dict]:
        if topic not in self._decoded and self._encodings.get(topic) == "protobuf":
            from pipeline.recording import joint_state_batch as JSB

            try:  # robocal's one protobuf channel, in its JSON form
                self._decoded[topic] = [JSB.to_dict(b, i) for i, b in enumerate(self.raw[topic])]
            except JSB.BatchError as e:
                raise RobocalError(f"{where(self._path, topic, e.record)}: {e.why}") from None
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
    encodings: dict[str, str] = field(default_factory=dict)  # topic -> the channel's message encoding
    warnings: list[str] = field(default_factory=list)
    complete: bool = False  # the footer was reached
    registration: dict[str, str] = field(default_factory=dict)  # topic -> '' or what is wrong with its schema
    profile: str = ""

    def __post_init__(self) -> None:
        if self.messages is None:
            self.messages = LazyMessages(self.path, self.encodings)

    def require(self, topic: str) -> list[dict]:
        if not self.messages.raw.get(topic):
            raise RobocalError(self.missing(topic))
        if self.registration.get(topic):
            raise RobocalError(f"{where(self.path, topic)}: {self.registration[topic]}")
        return self.messages[topic]

    def missing(self, topic: str) -> str:
        """'file: channel T: channel missing or empty (channels present: …)', one line whatever the
        topics hold (control characters escaped, each topic cut at 80 characters, at most 12 listed)."""
        names = sorted(self.messages.raw)
        have = ", ".join(_printable(t) for t in names[:12]) + (f", … ({len(names) - 12} more)" if len(names) > 12 else "")
        return f"{where(self.path, topic)}: channel missing or empty (channels present: {have or 'none'})"

    def meta(self, name: str) -> dict:
        if name not in self.metadata:
            raise RobocalError(f"{self.path}: metadata record {name!r} missing (not a robocal recording?)")
        return self.metadata[name]


def _printable(topic: str) -> str:
    """A topic as it can be printed on one line: control and non-printable characters escaped, ≤ 80 characters."""
    out = topic if topic.isprintable() else repr(topic)[1:-1]
    return out if len(out) <= 80 else out[:79] + "…"


def read_recording(path: str | Path, topics: set[str] | None = None, skip: frozenset[str] = frozenset(),
                   limits: ReadLimits | None = None, foreign: bool = False) -> Recording:
    """Read every complete record (messages of `topics`, or all, less those of `skip`) and the metadata.

    A damaged chunk (bad framing, CRC, compression, or over `limits`) is skipped with a warning and
    reading carries on at the next intact chunk; the messages read are compared with the summary's
    counts per channel.  Inside `cached_reads()` a second read of the same unchanged file is served
    from memory (a run reads its recording once).  `foreign`: any MCAP file (a ROS 2 bag's storage
    file being salvaged), not only robocal's recordings."""
    path = Path(path)
    from pipeline.ros2.kind import not_a_recording_hint

    if not foreign and (hint := not_a_recording_hint(path)) is not None:
        raise RobocalError(hint)
    if not path.is_file():
        raise RobocalError(f"{path}: no such file")
    key = None
    if _CACHE is not None:
        st = path.stat()
        key = (str(path.resolve()), st.st_size, st.st_mtime_ns, None if topics is None else frozenset(topics), skip)
        if key in _CACHE:
            return _CACHE[key]
    try:
        buf = path.read_bytes()
    except OSError as e:
        raise RobocalError(f"{path}: cannot read ({type(e).__name__}: {e.strerror or e})") from None
    if buf[:len(MAGIC)] != MAGIC:
        raise RobocalError(f"{path}: not an MCAP file (bad magic bytes)")
    rec = _Reader(path, buf, topics, skip, limits or ReadLimits.from_env()).read()
    if _CACHE is not None:
        _CACHE.clear()  # one recording at a time
        _CACHE[key] = rec
    return rec


_CACHE: dict | None = None


@contextmanager
def cached_reads() -> Iterator[None]:
    """Within this block, `read_recording` of an unchanged file is read and decompressed once."""
    global _CACHE
    outer = _CACHE
    if outer is None:
        _CACHE = {}
    try:
        yield
    finally:
        if outer is None:
            _CACHE = None


class _Reader:
    """One pass over a file's records (see `read_recording`)."""

    def __init__(self, path: Path, buf: bytes, topics, skip, limits: ReadLimits) -> None:
        self.path, self.buf, self.topics, self.skip, self.limits = path, buf, topics, skip, limits
        self.rec = Recording(path=path)
        self.channels: dict[int, Channel] = {}
        self.schemas: dict[int, Schema] = {}
        self.counts: dict[int, int] = {}  # channel id -> messages read (before topic filtering)
        self.unknown: dict[int, int] = {}  # channel id -> messages on a channel never defined
        self.summary = F.read_summary(buf)
        self.n = 0  # records read
        self.total = 0  # bytes decompressed

    def warn(self, pos: int, what: str) -> None:
        self.rec.warnings.append(f"{self.path}: byte {pos}: {what}")

    def read(self) -> Recording:
        buf, pos, end = self.buf, len(MAGIC), len(self.buf)
        while pos < end and not self.rec.complete:
            if end - pos < 9:
                self.warn(pos, f"file is truncated inside a record header; kept every complete record ({self._kept()} messages)")
                break
            op = buf[pos]
            (length,) = F._U64.unpack_from(buf, pos + 1)
            ok = (op in F.VALID_OPCODES or op >= 0x80) and pos + 9 + length <= end
            if ok:
                try:
                    self.record(op, memoryview(buf)[pos + 9:pos + 9 + length], pos)
                    pos += 9 + length
                    continue
                except F.Damaged as e:
                    what = f"damaged {e}"
                    nxt = pos + 9 + length
                    if nxt == end or F.frames_record(buf, nxt):  # the framing around it holds: skip just it
                        lost = "its messages are lost" if op == F.OP_CHUNK else "skipped it"
                        self.warn(pos, f"{what}; {lost}; kept every other complete record")
                        pos = nxt
                        continue
            elif op in F.VALID_OPCODES or op >= 0x80:
                what = f"file is truncated or damaged (record of {length} bytes runs past the end of the file)"
            else:
                what = f"file is truncated or damaged (no record starts here: opcode 0x{op:02x})"
            nxt = F.next_chunk(buf, pos, self.summary, self.limits)
            lost = f"messages up to byte {nxt} are lost" if nxt is not None else "nothing readable follows"
            self.warn(pos, f"{what}; {lost}; kept every other complete record")
            if nxt is None:
                break
            pos = nxt
        self.finish()
        return self.rec

    def _kept(self) -> int:
        return sum(len(v) for v in self.rec.messages.raw.values())

    def record(self, op: int, content, pos: int) -> None:
        self.n += 1
        if op == F.OP_CHUNK:
            head = F.parse_chunk_head(content)
            data = F.decompress_chunk(content, head, self.limits, self.total)
            self.total += len(data)
            inner = list(F.iter_inner(data))  # framing checked before any record is used
            for iop, icontent in inner:
                self.record(iop, icontent, pos)
        elif op == F.OP_MESSAGE:
            cid, log_time, data = F.parse_message(content)
            ch = self.channels.get(cid) or self.summary.channels.get(cid)
            if ch is None:
                self.unknown[cid] = self.unknown.get(cid, 0) + 1
                return
            if cid not in self.channels:
                self.channel(ch)
            self.counts[cid] = self.counts.get(cid, 0) + 1
            if (self.topics is not None and ch.topic not in self.topics) or ch.topic in self.skip:
                return
            self.rec.messages.raw[ch.topic].append(data)
            self.rec.log_times.setdefault(ch.topic, []).append(log_time)
        elif op == F.OP_CHANNEL:
            self.channel(F.read_content(Channel, content))
        elif op == F.OP_SCHEMA:
            s = F.read_content(Schema, content)
            self.schemas[s.id] = s
        elif op == F.OP_METADATA:
            self.metadata(F.read_content(Metadata, content), pos)
        elif op == F.OP_HEADER:
            self.rec.profile = F.read_content(Header, content).profile
        elif op == F.OP_FOOTER:
            if bytes(self.buf[pos + 9 + len(content):]) != MAGIC:  # a footer closes the file: magic and nothing else follow
                raise F.Damaged("footer record that does not close the file")
            self.rec.complete = True

    def channel(self, ch: Channel) -> None:
        self.channels[ch.id] = ch
        s = self.schemas.get(ch.schema_id) or self.summary.schemas.get(ch.schema_id)
        self.rec.schemas[ch.topic] = (s.name if s else "", s.encoding if s else "")
        self.rec.encodings[ch.topic] = ch.message_encoding
        self.rec.registration[ch.topic] = registration_problem(ch, s)
        self.rec.messages.raw.setdefault(ch.topic, [])

    def metadata(self, r: Metadata, pos: int) -> None:
        if r.name in self.rec.metadata:
            raise RobocalError(f"{self.path}: byte {pos}: metadata record {r.name!r} appears twice "
                               "(a recording holds one; which one to trust is not known)")
        raw = r.metadata.get("json")
        try:
            value = json.loads(raw) if raw is not None else dict(r.metadata)
        except (ValueError, RecursionError):
            raise RobocalError(f"{self.path}: metadata {r.name!r} is not valid JSON") from None
        if not isinstance(value, dict):
            raise RobocalError(f"{self.path}: metadata {r.name!r} is not a JSON object")
        self.rec.metadata[r.name] = value

    def finish(self) -> None:
        rec = self.rec
        for cid, k in sorted(self.unknown.items()):
            rec.warnings.append(f"{self.path}: {k} messages on channel id {cid}, whose channel record was "
                                "lost, dropped")
        expected = self.summary.message_counts
        if expected is not None:
            for cid, want in sorted(expected.items()):
                got = self.counts.get(cid, 0)
                if got != want:
                    ch = self.channels.get(cid) or self.summary.channels.get(cid)
                    name = ch.topic if ch else f"id {cid}"
                    rec.warnings.append(f"{where(self.path, name)}: read {got} of the {want} messages the "
                                        f"summary lists ({want - got} lost in damaged records)")
        if not rec.complete and not rec.warnings:
            rec.warnings.append(f"{self.path}: file has no footer (not closed cleanly); kept every complete record")


def registration_problem(ch: Channel, schema: Schema | None) -> str:
    """'' when a robocal channel is registered as robocal writes it (JSON messages, its JSON Schema;
    the encoder stream: protobuf `robocal.JointStateBatch` with its FileDescriptorSet, or JSON as
    archived recordings have it), else what is wrong.  Channels robocal does not know are only
    required to carry JSON."""
    from pipeline.recording import joint_state_batch as JSB
    from pipeline.recording.schemas import CHANNELS, STREAM, schema_title

    if ch.topic == STREAM and ch.message_encoding == JSB.ENCODING:
        if schema is None:
            return f"no schema registered (expected {JSB.SCHEMA_NAME!r}, protobuf)"
        return JSB.descriptor_problem(schema.name, schema.encoding, schema.data)
    if ch.message_encoding != "json":
        also = " (or 'protobuf' on /robot/joint_state)" if ch.topic == STREAM else ""
        return f"message_encoding is {ch.message_encoding!r}, robocal reads 'json'{also}"
    stem = CHANNELS.get(ch.topic)
    if stem is None:
        return ""
    if schema is None:
        return f"no schema registered (expected {schema_title(stem)!r}, jsonschema)"
    if schema.encoding != "jsonschema" or schema.name != schema_title(stem):
        return (f"registered schema is {schema.name!r} ({schema.encoding}), expected {schema_title(stem)!r} "
                "(jsonschema)")
    try:
        doc = json.loads(schema.data)
    except (ValueError, RecursionError, UnicodeDecodeError):
        return "registered schema is not valid JSON"
    if not isinstance(doc, dict) or doc.get("title") != schema_title(stem):
        return f"registered schema's content is not the {schema_title(stem)!r} JSON Schema"
    return ""
