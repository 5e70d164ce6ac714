"""robocal serial wire protocol v1: framing, payload codecs and a resynchronising decoder.

Pure functions and a pure incremental decoder (bytes in, frames and error reports out);
no ports here.  The byte layout is documented in `docs/guide/acquire.md`.

Frame (all integers little-endian)::

    off  size  field
    0    2     sync  0xA5 0x5A
    2    1     type  (FrameType)
    3    1     version (1)
    4    4     seq   uint32, per device link, +1 per frame (wraps)
    8    8     device_time_ns  int64, device clock when the frame was sent
    16   2     payload length N (<= MAX_PAYLOAD)
    18   2     header CRC-16/CCITT (binascii.crc_hqx, init 0xFFFF) of bytes 2..17
    20   N     payload
    20+N 4     CRC-32 (zlib.crc32) of bytes 2..20+N-1

The header CRC rejects a corrupted length at once, so a damaged frame never makes the
decoder wait for (or swallow) the frames behind it; the decoder then rescans from the byte
after the bad sync word, so every frame whose own bytes are intact is recovered.
"""

from __future__ import annotations

import binascii
import json
import struct
import zlib
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from pipeline.recording.joint_state_batch import OPTIONAL_SAMPLES

SYNC = b"\xa5\x5a"
VERSION = 1
HEADER = struct.Struct("<2sBBIqHH")  # sync, type, version, seq, device_time_ns, length, header crc
HEADER_SIZE = HEADER.size  # 20
CRC_SIZE = 4
MAX_PAYLOAD = 60_000
SEQ_MOD = 1 << 32


class FrameType(IntEnum):
    HELLO = 0x01  # JSON: device role, system, joint names, channels it sends
    META = 0x02  # fragment of a metadata document (name, part, parts, doc crc, bytes)
    CAMPAIGN_START = 0x03  # JSON: system, expected sample/event counts
    CAMPAIGN_END = 0x04  # JSON: totals sent
    HEARTBEAT = 0x05  # empty: device time only (clock sync while idle)
    SAMPLES = 0x10  # binary encoder samples with controller timestamps
    SAMPLES_DRIVE = 0x11  # SAMPLES plus the drive state: commanded positions, efforts, motor currents
    EVENT = 0x20  # a measurement event of a channel: device time, topic, JSON body


KNOWN_TYPES = frozenset(int(t) for t in FrameType)


@dataclass(frozen=True)
class Frame:
    """One verified frame; `offset` is the byte position of its sync word in the link stream."""

    type: FrameType
    seq: int
    device_time_ns: int
    payload: bytes
    offset: int


@dataclass(frozen=True)
class BadFrame:
    """A sync word whose header or payload failed its checksum (at stream byte `offset`)."""

    offset: int
    reason: str


@dataclass(frozen=True)
class Garbage:
    """`n` bytes at stream byte `offset` that belong to no valid frame."""

    offset: int
    n: int


def _hcrc(b: bytes | memoryview) -> int:
    return binascii.crc_hqx(b, 0xFFFF)


def encode_frame(ftype: int, seq: int, device_time_ns: int, payload: bytes = b"") -> bytes:
    """One frame's bytes."""
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
    head = struct.pack("<BBIqH", int(ftype), VERSION, seq % SEQ_MOD, int(device_time_ns), len(payload))
    body = head + struct.pack("<H", _hcrc(head)) + payload
    return SYNC + body + struct.pack("<I", zlib.crc32(body))


class FrameDecoder:
    """Incremental decoder: `feed(bytes)` returns the frames completed by those bytes and
    the problems found (`BadFrame`, `Garbage`), each with its stream byte offset.

    Never returns a frame whose header or payload checksum fails."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self._base = 0  # stream offset of _buf[0]
        self.bytes_in = 0
        self.garbage_bytes = 0
        self.bad_frames = 0

    def feed(self, data: bytes) -> tuple[list[Frame], list[BadFrame | Garbage]]:
        self._buf += data
        self.bytes_in += len(data)
        frames: list[Frame] = []
        problems: list[BadFrame | Garbage] = []
        buf = self._buf
        view = memoryview(buf)
        n = len(buf)
        pos = 0
        junk = -1  # start of the current run of bytes that belong to no valid frame

        def flush_junk(upto: int) -> None:
            nonlocal junk
            if 0 <= junk < upto:
                problems.append(Garbage(self._base + junk, upto - junk))
                self.garbage_bytes += upto - junk
            junk = -1

        try:
            while True:
                i = buf.find(SYNC, pos)
                if i < 0:  # keep a trailing first sync byte; the rest is garbage
                    keep = max(pos, n - 1 if n and buf[-1] == SYNC[0] else n)
                    if junk < 0 and keep > pos:
                        junk = pos
                    flush_junk(keep)
                    pos = keep
                    break
                if i > pos and junk < 0:
                    junk = pos
                if n - i < HEADER_SIZE:
                    flush_junk(i)
                    pos = i
                    break
                _, ftype, ver, seq, dtime, length, hcrc = HEADER.unpack_from(buf, i)
                reason = ""
                if _hcrc(view[i + 2:i + 18]) != hcrc or ver != VERSION or ftype not in KNOWN_TYPES \
                        or length > MAX_PAYLOAD:
                    reason = "header checksum"
                else:
                    end = i + HEADER_SIZE + length + CRC_SIZE
                    if n < end:
                        flush_junk(i)
                        pos = i
                        break
                    (crc,) = struct.unpack_from("<I", buf, end - CRC_SIZE)
                    if zlib.crc32(view[i + 2:end - CRC_SIZE]) != crc:
                        reason = "payload checksum"
                if reason:
                    problems.append(BadFrame(self._base + i, reason))
                    self.bad_frames += 1
                    if junk < 0:
                        junk = i
                    pos = i + 1
                    continue
                flush_junk(i)
                frames.append(Frame(FrameType(ftype), seq, dtime, bytes(view[i + HEADER_SIZE:end - CRC_SIZE]),
                                    self._base + i))
                pos = end
        finally:
            view.release()
        del buf[:pos]
        self._base += pos
        return frames, problems

    def finish(self) -> list[Garbage]:
        """End of stream (disconnect): whatever is buffered is garbage."""
        out = [Garbage(self._base, len(self._buf))] if self._buf else []
        self.garbage_bytes += len(self._buf)
        self._base += len(self._buf)
        self._buf.clear()
        return out


# ----- sequence tracking ------------------------------------------------------------------
@dataclass
class SeqTracker:
    """Detects missing frames from the sequence numbers of one link."""

    expected: int | None = None
    received: int = 0
    missing: int = 0
    gaps: list[tuple[int, int, int]] = field(default_factory=list)  # (first missing seq, count, stream offset)

    def see(self, seq: int, offset: int) -> int:
        """Register frame `seq`; returns how many frames were skipped before it."""
        self.received += 1
        lost = 0
        if self.expected is not None:
            lost = (seq - self.expected) % SEQ_MOD
            if lost > SEQ_MOD // 2:  # went backwards: a device restart; not counted as loss
                lost = 0
            if lost:
                self.missing += lost
                self.gaps.append((self.expected, lost, offset))
        self.expected = (seq + 1) % SEQ_MOD
        return lost


# ----- payload codecs ---------------------------------------------------------------------
def encode_json(doc: dict) -> bytes:
    return json.dumps(doc, separators=(",", ":")).encode()


def decode_json(payload: bytes) -> dict:
    return json.loads(payload)


_SAMPLES_HEAD = struct.Struct("<BH")  # n_joints, n_samples


def encode_samples(t_ns: np.ndarray, q: np.ndarray) -> bytes:
    """SAMPLES payload: uint8 n_joints, uint16 n_samples, int64[n] controller times (ns,
    device clock), float64[n, n_joints] joint positions (rad), row-major."""
    t = np.ascontiguousarray(t_ns, dtype="<i8")
    q = np.ascontiguousarray(q, dtype="<f8")
    if q.ndim != 2 or q.shape[0] != t.size:
        raise ValueError("q must be (n_samples, n_joints)")
    return _SAMPLES_HEAD.pack(q.shape[1], t.size) + t.tobytes() + q.tobytes()


def decode_samples(payload: bytes) -> tuple[np.ndarray, np.ndarray]:
    nj, ns = _SAMPLES_HEAD.unpack_from(payload, 0)
    o = _SAMPLES_HEAD.size
    if len(payload) != o + 8 * ns + 8 * ns * nj:
        raise ValueError(f"SAMPLES payload of {len(payload)} bytes does not hold {ns} x {nj} samples")
    t = np.frombuffer(payload, "<i8", ns, o).astype(np.int64)
    q = np.frombuffer(payload, "<f8", ns * nj, o + 8 * ns).reshape(ns, nj).astype(float)
    return t, q


# drive state of SAMPLES_DRIVE: flag bit → JointStream / RecordingWriter.write_batch keyword, in payload order
DRIVE_FIELDS = ("q_cmd", "effort", "current")  # commanded positions rad / m, efforts N·m / N, motor currents A
DRIVE_NAMES = OPTIONAL_SAMPLES  # robocal.JointStateBatch fields 7, 8, 9, in DRIVE_FIELDS' order
_DRIVE_HEAD = struct.Struct("<BHB")  # n_joints, n_samples, flags


def samples_drive_size(n: int, n_joints: int, n_arrays: int) -> int:
    """Payload bytes of a SAMPLES_DRIVE frame of `n` samples carrying `n_arrays` drive arrays."""
    return _DRIVE_HEAD.size + 8 * n + 8 * n * n_joints * (1 + n_arrays)


def max_drive_samples(n_joints: int, n_arrays: int) -> int:
    """Most samples one SAMPLES_DRIVE frame holds within MAX_PAYLOAD (a device splits larger batches)."""
    return (MAX_PAYLOAD - _DRIVE_HEAD.size) // (8 + 8 * n_joints * (1 + n_arrays))


def encode_samples_drive(t_ns: np.ndarray, q: np.ndarray, drive: dict[str, np.ndarray]) -> bytes:
    """SAMPLES_DRIVE payload: uint8 n_joints, uint16 n_samples, uint8 flags (bit 0 commanded positions,
    bit 1 efforts, bit 2 motor currents), int64[n] controller times (ns, device clock), float64[n, n_joints]
    joint positions (rad), then for each set bit in bit order float64[n, n_joints] (rad / m, N·m / N, A),
    row-major.  `drive` maps `DRIVE_FIELDS` keys to (n, n_joints) arrays; None values are left out."""
    head = encode_samples(t_ns, q)
    nj, n = head[0], int(np.asarray(t_ns).size)
    flags, body = 0, []
    for bit, key in enumerate(DRIVE_FIELDS):
        v = drive.get(key)
        if v is None:
            continue
        v = np.ascontiguousarray(v, dtype="<f8")
        if v.shape != (n, nj):
            raise ValueError(f"{key} must be ({n}, {nj}), not {v.shape}")
        flags |= 1 << bit
        body.append(v.tobytes())
    return _DRIVE_HEAD.pack(nj, n, flags) + head[_SAMPLES_HEAD.size:] + b"".join(body)


def decode_samples_drive(payload: bytes) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """(times (n,) ns, positions (n, n_joints) rad, {DRIVE_FIELDS key: (n, n_joints)} for the set flags).
    A payload whose length is not what its header declares, or with an undefined flag bit, is a ValueError."""
    nj, ns, flags = _DRIVE_HEAD.unpack_from(payload, 0)
    if flags >> len(DRIVE_FIELDS):
        raise ValueError(f"SAMPLES_DRIVE flags 0x{flags:02x} set undefined bits")
    keys = [k for bit, k in enumerate(DRIVE_FIELDS) if flags >> bit & 1]
    if len(payload) != samples_drive_size(ns, nj, len(keys)):
        raise ValueError(f"SAMPLES_DRIVE payload of {len(payload)} bytes does not hold {ns} x {nj} samples "
                         f"with {len(keys)} drive arrays")
    o = _DRIVE_HEAD.size
    t = np.frombuffer(payload, "<i8", ns, o).astype(np.int64)
    o += 8 * ns
    arrays = [np.frombuffer(payload, "<f8", ns * nj, o + 8 * ns * nj * k).reshape(ns, nj).astype(float)
              for k in range(1 + len(keys))]
    for k, a in zip(keys, arrays[1:]):  # the stream's schema holds finite drive values only: one NaN would
        if not np.all(np.isfinite(a)):  # make the whole encoder stream unreadable, so the frame is rejected
            raise ValueError(f"SAMPLES_DRIVE {k} hold NaN or inf")
    return t, arrays[0], dict(zip(keys, arrays[1:]))


def decode_any_samples(ftype: int, payload: bytes) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """A SAMPLES or SAMPLES_DRIVE payload as (times, positions, drive state ({} for SAMPLES))."""
    if ftype == FrameType.SAMPLES_DRIVE:
        return decode_samples_drive(payload)
    return (*decode_samples(payload), {})


_EVENT_HEAD = struct.Struct("<qB")  # device event time, topic length


def encode_event(t_ns: int, topic: str, body: dict) -> bytes:
    """EVENT payload: int64 event time (device clock, ns), uint8 topic length, topic (UTF-8),
    JSON message body (the channel's schema, without timestamp fields)."""
    tb = topic.encode()
    return _EVENT_HEAD.pack(int(t_ns), len(tb)) + tb + encode_json(body)


def decode_event(payload: bytes) -> tuple[int, str, dict]:
    t, nt = _EVENT_HEAD.unpack_from(payload, 0)
    o = _EVENT_HEAD.size
    topic = payload[o:o + nt].decode()
    body = json.loads(payload[o + nt:])
    if not isinstance(body, dict):
        raise ValueError("EVENT body is not a JSON object")
    return t, topic, body


_META_HEAD = struct.Struct("<BHHI")  # name length, part, parts, crc32 of the whole document


def encode_meta_parts(name: str, text: str, part_size: int = 400) -> list[bytes]:
    """META payloads: a metadata document split into parts of `part_size` bytes.  Each:
    uint8 name length, uint16 part, uint16 parts, uint32 CRC-32 of the whole document,
    name (UTF-8), the part's bytes."""
    doc = text.encode()
    crc = zlib.crc32(doc)
    nb = name.encode()
    chunks = [doc[i:i + part_size] for i in range(0, len(doc), part_size)] or [b""]
    return [_META_HEAD.pack(len(nb), k, len(chunks), crc) + nb + c for k, c in enumerate(chunks)]


def decode_meta_part(payload: bytes) -> tuple[str, int, int, int, bytes]:
    """(name, part, parts, document crc, bytes)."""
    nn, part, parts, crc = _META_HEAD.unpack_from(payload, 0)
    o = _META_HEAD.size
    return payload[o:o + nn].decode(), part, parts, crc, payload[o + nn:]


@dataclass
class MetaAssembler:
    """Collects META parts (repeated by the device) into whole documents, checked by CRC."""

    parts: dict[str, dict[int, bytes]] = field(default_factory=dict)
    done: dict[str, str] = field(default_factory=dict)

    def add(self, payload: bytes) -> tuple[str, str] | None:
        """Returns (name, text) the first time a document is complete."""
        name, part, parts, crc, data = decode_meta_part(payload)
        if name in self.done:
            return None
        got = self.parts.setdefault(name, {})
        got[part] = data
        if len(got) == parts and all(k in got for k in range(parts)):
            doc = b"".join(got[k] for k in range(parts))
            if zlib.crc32(doc) != crc:  # parts of two different versions: start over
                self.parts[name] = {}
                return None
            self.done[name] = doc.decode()
            return name, self.done[name]
        return None
