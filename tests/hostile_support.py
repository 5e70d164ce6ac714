"""Build damaged and hostile recordings from the bundled ones: byte-level damage to
MCAP framing and chunks, and content-level edits written with the `mcap` writer as a hostile
device or tool would (any topic, schema, encoding, JSON text, metadata)."""

from __future__ import annotations

import io
import json
import struct
from pathlib import Path

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.records import Chunk
from mcap.writer import CompressionType, Writer

from pipeline.recording import joint_state_batch as JSB
from pipeline.recording.reader import read_recording
from pipeline.recording.schemas import CHANNELS, schema_bytes, schema_title

ROOT = Path(__file__).resolve().parent.parent
BUNDLED = {name: ROOT / "recordings" / f"{name}.mcap" for name in ("arc-welder-touch", "delta-tracker",
                                                                  "scorbot-scanner")}
_U64 = struct.Struct("<Q")


def top_records(buf: bytes) -> list[tuple[int, int, int]]:
    """(offset, opcode, length) of every top-level record of a well-formed file."""
    out, p = [], 8
    while p + 9 <= len(buf) - 8:
        op, (n,) = buf[p], _U64.unpack_from(buf, p + 1)
        out.append((p, op, n))
        p += 9 + n
    return out


def chunk_offsets(buf: bytes) -> list[int]:
    return [p for p, op, _ in top_records(buf) if op == 0x06]


def replace_chunk(buf: bytes, k: int, edit) -> bytes:
    """The file with its k-th chunk record replaced by `edit(Chunk) -> Chunk` (sizes may change:
    later offsets, hence the summary's index, then no longer hold)."""
    p = chunk_offsets(buf)[k]
    (n,) = _U64.unpack_from(buf, p + 1)
    chunk = Chunk.read(ReadDataStream(io.BytesIO(buf[p + 9:p + 9 + n])))
    from mcap.data_stream import RecordBuilder

    b = RecordBuilder()
    edit(chunk).write(b)
    return buf[:p] + b.end() + buf[p + 9 + n:]


def bomb(kind: str = "zstd", size: int = 1 << 30):
    """A chunk edit: its data becomes a small frame of `size` zero bytes."""
    def edit(c: Chunk) -> Chunk:
        if kind == "zstd":
            import zstandard
            cctx = zstandard.ZstdCompressor(level=19)
            with io.BytesIO() as out:
                with cctx.stream_writer(out, closefd=False, size=size) as w:
                    block = bytes(1 << 24)
                    for _ in range(size // len(block)):
                        w.write(block)
                data = out.getvalue()
        else:
            import lz4.frame
            comp = lz4.frame.LZ4FrameCompressor()
            parts = [comp.begin(source_size=size)]
            block = bytes(1 << 24)
            parts += [comp.compress(block) for _ in range(size // len(block))]
            parts.append(comp.flush())
            data = b"".join(parts)
        return Chunk(compression=kind, data=data, message_end_time=c.message_end_time,
                     message_start_time=c.message_start_time, uncompressed_crc=0, uncompressed_size=size)
    return edit


def rebuild(src: Path, dst: Path, *, msg=None, meta=None, channel=None, extra=(), compression=CompressionType.ZSTD,
            chunk_size: int = 1 << 20) -> Path:
    """Rewrite `src` into `dst` with the `mcap` writer.

    msg(topic, i, data: bytes) -> bytes | None (None drops it); meta(dict name -> dict) -> list of
    (name, dict | str); channel(topic) -> dict overriding topic / schema_name / schema_encoding /
    schema_data / message_encoding; extra: (topic, log_time_ns, data) messages added."""
    rec = read_recording(src)
    msgs = [(t, lt, i, d) for t in rec.messages.raw for i, (lt, d) in enumerate(zip(rec.log_times[t], rec.messages.raw[t]))]
    msgs += [(t, lt, -1, d) for t, lt, d in extra]
    msgs.sort(key=lambda m: m[1])
    with open(dst, "wb") as f:
        w = Writer(f, compression=compression, chunk_size=chunk_size)
        w.start(profile="robocal", library="hostile")
        items = meta(dict(rec.metadata)) if meta else list(rec.metadata.items())
        for name, value in items:
            w.add_metadata(name, {"json": value if isinstance(value, str) else json.dumps(value)})
        ids: dict[str, int] = {}
        for t, lt, i, d in msgs:
            if t not in ids:
                stem = CHANNELS.get(t)
                spec = {"topic": t, "schema_name": schema_title(stem) if stem else "custom",
                        "schema_encoding": "jsonschema", "schema_data": schema_bytes(stem) if stem else b"{}",
                        "message_encoding": "json"}
                if rec.encodings.get(t) == JSB.ENCODING:  # the protobuf encoder stream, registered as robocal does
                    spec.update(schema_name=JSB.SCHEMA_NAME, schema_encoding=JSB.ENCODING,
                                schema_data=JSB.FILE_DESCRIPTOR_SET, message_encoding=JSB.ENCODING)
                spec.update(channel(t) if channel else {})
                sid = w.register_schema(spec["schema_name"], spec["schema_encoding"], spec["schema_data"])
                ids[t] = w.register_channel(spec["topic"], spec["message_encoding"], sid)
            d = msg(t, i, d) if (msg and i >= 0) else d
            if d is not None:
                w.add_message(ids[t], log_time=lt, data=d, publish_time=lt)
        w.finish()
    return dst


def edit_json(topic: str, index: int, fn):
    """A `msg` edit applying `fn(body: dict) -> dict | bytes` to message `index` of `topic`."""
    def edit(t, i, data):
        if t != topic or i != index:
            return data
        out = fn(json.loads(data))
        return out if isinstance(out, bytes) else json.dumps(out).encode()
    return edit


def bit_flips(buf: bytes, rng: np.random.Generator, n: int) -> bytes:
    b = bytearray(buf)
    for p in rng.integers(8, len(b) - 8, n):
        b[p] ^= 1 << int(rng.integers(8))
    return bytes(b)
