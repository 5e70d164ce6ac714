"""MCAP record framing for damaged files: top-level records, chunks with bounded decompression,
the summary section, and re-synchronisation after damage.

Every top-level MCAP record is `opcode (u8) · length (u64 LE) · content`; a chunk's content is
`start, end (u64) · uncompressed size (u64) · uncompressed CRC (u32) · compression (string) ·
records (u64-prefixed bytes)`.  This module reads those framings itself (with the `mcap` library's
record classes for the record contents) so that it can

* check a chunk's declared sizes against `ReadLimits` *before* decompressing it, and cap the
  decompressor's output at the declared size (a frame that lies about its size cannot expand);
* skip one damaged chunk and carry on with the next intact one, found through the summary's chunk
  index when the footer is intact, else by scanning for the next record that frames as a chunk.
"""

from __future__ import annotations

import io
import os
import struct
import zlib
from dataclasses import dataclass, field

from mcap.data_stream import ReadDataStream
from mcap.records import Channel, ChunkIndex, Footer, MetadataIndex, Schema, Statistics

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
OP_CHUNK_INDEX, OP_METADATA, OP_METADATA_INDEX, OP_STATISTICS, OP_DATA_END = 0x08, 0x0C, 0x0D, 0x0B, 0x0F
VALID_OPCODES = frozenset(range(0x01, 0x10))  # 0x80–0xFF are private records (skipped); the rest is damage
COMPRESSIONS = ("", "zstd", "lz4")
_U64 = struct.Struct("<Q")
_CHUNK_HEAD = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, compression length
_MSG_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
MiB = 1 << 20


class Damaged(Exception):
    """A record whose framing or content is inconsistent (the message says what and where)."""


def _env_number(name: str, default: float) -> float:
    raw = os.environ.get(name)
    if raw is None or raw == "":
        return default
    try:
        v = float(raw)
    except ValueError:
        from pipeline.errors import RobocalError
        raise RobocalError(f"environment variable {name}={raw!r} is not a number") from None
    return v


@dataclass(frozen=True)
class ReadLimits:
    """Bounds on what one recording may decompress to (checked before decompressing).

    `max_chunk_bytes`: one chunk's uncompressed size; `max_ratio`: uncompressed / compressed size
    of a chunk larger than `ratio_floor_bytes` (JSON telemetry compresses 3–20×; a zstd frame of
    zeros 10⁴×); `max_total_bytes`: all chunks of the file together.  Defaults from the
    environment: ROBOCAL_MAX_CHUNK_MB (256), ROBOCAL_MAX_RATIO (100), ROBOCAL_MAX_UNCOMPRESSED_MB (1024).
    """

    max_chunk_bytes: int = 256 * MiB
    max_ratio: float = 100.0
    max_total_bytes: int = 1024 * MiB
    ratio_floor_bytes: int = 1 * MiB

    @classmethod
    def from_env(cls) -> "ReadLimits":
        return cls(max_chunk_bytes=int(_env_number("ROBOCAL_MAX_CHUNK_MB", 256) * MiB),
                   max_ratio=_env_number("ROBOCAL_MAX_RATIO", 100.0),
                   max_total_bytes=int(_env_number("ROBOCAL_MAX_UNCOMPRESSED_MB", 1024) * MiB))


@dataclass
class ChunkHead:
    """A chunk's framing, parsed without touching its compressed data."""

    uncompressed_size: int
    crc: int
    compression: str
    data_start: int  # offset of the compressed bytes within the record content
    data_len: int


def parse_chunk_head(content: bytes) -> ChunkHead:
    if len(content) < _CHUNK_HEAD.size:
        raise Damaged("chunk record shorter than its fixed fields")
    _, _, usize, crc, clen = _CHUNK_HEAD.unpack_from(content, 0)
    p = _CHUNK_HEAD.size
    if clen > 16 or p + clen + 8 > len(content):
        raise Damaged(f"chunk compression field of {clen} bytes")
    try:
        comp = bytes(content[p:p + clen]).decode("utf-8")
    except UnicodeDecodeError:
        raise Damaged("chunk compression field is not text") from None
    p += clen
    (dlen,) = _U64.unpack_from(content, p)
    p += 8
    if p + dlen != len(content):
        raise Damaged(f"chunk data of {dlen} bytes does not fit its record of {len(content)} bytes")
    return ChunkHead(usize, crc, comp, p, dlen)


def decompress_chunk(content: bytes, head: ChunkHead, limits: ReadLimits, total_so_far: int) -> bytes:
    """The chunk's records, decompressed with the output capped at the declared size.
    Raises `Damaged` for an unknown compression, a size or ratio over `limits` (before any
    decompression), a frame that expands past its declared size, or a CRC mismatch."""
    if head.compression not in COMPRESSIONS:
        raise Damaged(f"unknown chunk compression {head.compression!r}")
    n = head.uncompressed_size
    if n > limits.max_chunk_bytes:
        raise Damaged(f"chunk declares {n / MiB:.0f} MiB uncompressed, over the limit of "
                      f"{limits.max_chunk_bytes / MiB:.0f} MiB (ROBOCAL_MAX_CHUNK_MB); not decompressed")
    if n > limits.ratio_floor_bytes and n > limits.max_ratio * max(head.data_len, 1):
        raise Damaged(f"chunk declares a compression ratio of {n / max(head.data_len, 1):.0f}:1, over the "
                      f"limit of {limits.max_ratio:g}:1 (ROBOCAL_MAX_RATIO; a decompression bomb?); not decompressed")
    if total_so_far + n > limits.max_total_bytes:
        raise Damaged(f"the file's chunks exceed {limits.max_total_bytes / MiB:.0f} MiB uncompressed "
                      f"(ROBOCAL_MAX_UNCOMPRESSED_MB); not decompressed")
    data = content[head.data_start:head.data_start + head.data_len]
    try:
        if head.compression == "zstd":
            import zstandard
            with zstandard.ZstdDecompressor().stream_reader(io.BytesIO(data)) as r:
                out = r.read(n + 1)
        elif head.compression == "lz4":
            import lz4.frame
            out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=n + 1)
        else:
            out = bytes(data)
    except Exception as e:  # noqa: BLE001 — zstd/lz4 raise their own error types on bad frames
        raise Damaged(f"chunk does not decompress ({type(e).__name__}: {e})") from None
    if len(out) != n:
        raise Damaged(f"chunk expands to {'more than ' if len(out) > n else ''}{len(out)} bytes, "
                      f"it declares {n}")
    if head.crc != 0 and zlib.crc32(out) != head.crc:
        raise Damaged("chunk CRC mismatch")
    return out


def iter_inner(data: bytes):
    """(opcode, content) of each record inside a decompressed chunk; `Damaged` on bad framing."""
    p, end = 0, len(data)
    while p < end:
        if end - p < 9:
            raise Damaged(f"chunk ends inside a record header at byte {p}")
        op = data[p]
        (length,) = _U64.unpack_from(data, p + 1)
        if p + 9 + length > end:
            raise Damaged(f"record at byte {p} of the chunk runs past its end")
        yield op, data[p + 9:p + 9 + length]
        p += 9 + length


def parse_message(content: bytes) -> tuple[int, int, bytes]:
    """(channel id, log time ns, data) of a Message record's content."""
    if len(content) < _MSG_HEAD.size:
        raise Damaged("message record shorter than its fixed fields")
    cid, _, log_time, _ = _MSG_HEAD.unpack_from(content, 0)
    return cid, log_time, bytes(content[_MSG_HEAD.size:])


def read_content(cls, content: bytes):
    """A record of `mcap.records` class `cls` from its content bytes; `Damaged` on overrun."""
    try:
        stream = ReadDataStream(io.BytesIO(content))
        rec = cls.read(stream)
    except Exception as e:  # noqa: BLE001 — struct.error, UnicodeDecodeError, ... on garbage
        raise Damaged(f"{cls.__name__} record does not parse ({type(e).__name__})") from None
    if stream.count > len(content):
        raise Damaged(f"{cls.__name__} record runs past its length")
    return rec


@dataclass
class Summary:
    """What the summary section says (empty when the footer or summary is unreadable)."""

    chunk_offsets: list[int] = field(default_factory=list)
    metadata_offsets: list[int] = field(default_factory=list)
    message_counts: dict[int, int] | None = None  # channel id -> messages (Statistics)
    channels: dict[int, Channel] = field(default_factory=dict)
    schemas: dict[int, Schema] = field(default_factory=dict)
    summary_start: int | None = None


def read_summary(buf: bytes) -> Summary:
    """Parse the footer and summary section from the end of the file (best effort)."""
    s = Summary()
    foot = len(buf) - len(MAGIC) - 9 - 20
    if foot < len(MAGIC) or buf[-len(MAGIC):] != MAGIC or buf[foot] != OP_FOOTER:
        return s
    try:
        footer = read_content(Footer, buf[foot + 9:foot + 29])
    except Damaged:
        return s
    start = footer.summary_start
    if not (len(MAGIC) <= start <= foot):
        return s
    if footer.summary_crc != 0 and zlib.crc32(buf[start:foot + 9 + 8]) != footer.summary_crc:
        return s  # a damaged summary is no guide
    s.summary_start = start
    p = start
    while p + 9 <= foot:
        op = buf[p]
        (length,) = _U64.unpack_from(buf, p + 1)
        if p + 9 + length > foot:
            break
        content = buf[p + 9:p + 9 + length]
        try:
            if op == OP_CHUNK_INDEX:
                s.chunk_offsets.append(read_content(ChunkIndex, content).chunk_start_offset)
            elif op == OP_METADATA_INDEX:
                s.metadata_offsets.append(read_content(MetadataIndex, content).offset)
            elif op == OP_STATISTICS:
                s.message_counts = dict(read_content(Statistics, content).channel_message_counts)
            elif op == OP_CHANNEL:
                ch = read_content(Channel, content)
                s.channels[ch.id] = ch
            elif op == OP_SCHEMA:
                sc = read_content(Schema, content)
                s.schemas[sc.id] = sc
        except Damaged:
            pass
        p += 9 + length
    return s


def plausible_chunk(buf: bytes, p: int, limits: ReadLimits) -> bool:
    """Does a chunk record start at byte `p` (framing consistent, known compression, sizes in limits)?"""
    if p + 9 > len(buf) or buf[p] != OP_CHUNK:
        return False
    (length,) = _U64.unpack_from(buf, p + 1)
    if p + 9 + length > len(buf):
        return False
    try:
        head = parse_chunk_head(memoryview(buf)[p + 9:p + 9 + length])
    except Damaged:
        return False
    return head.compression in COMPRESSIONS and head.uncompressed_size <= limits.max_chunk_bytes


def frames_record(buf: bytes, p: int) -> bool:
    """Does a well-framed record (valid opcode, length within the file) start at byte `p`?"""
    if p + 9 > len(buf) or not (buf[p] in VALID_OPCODES or buf[p] >= 0x80):
        return False
    (length,) = _U64.unpack_from(buf, p + 1)
    return p + 9 + length <= len(buf)


def next_chunk(buf: bytes, after: int, summary: Summary, limits: ReadLimits) -> int | None:
    """Where to carry on after damage at byte `after`: the next chunk the summary's index knows,
    else the next byte that frames as a chunk; None when there is none."""
    known = [o for o in summary.chunk_offsets + summary.metadata_offsets if o > after]
    if summary.summary_start is not None and summary.summary_start > after:
        known.append(summary.summary_start)
    if known:
        return min(known)
    p = buf.find(bytes([OP_CHUNK]), after + 1)
    while p != -1:
        if plausible_chunk(buf, p, limits):
            return p
        p = buf.find(bytes([OP_CHUNK]), p + 1)
    return None
