"""Acquisition core: bytes of each device link (with host receive times) → recording.

No ports or signals here: the shell (`pipeline.acquire.run`) feeds `Acquisition.on_bytes`
and calls `tick()` at least every half second; each tick maps the pending device times to
the host clock (`ClockSync`), writes the messages and flushes a complete MCAP chunk.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from pipeline.acquire.clock import ClockSync
from pipeline.acquire.protocol import (DRIVE_FIELDS, DRIVE_NAMES, BadFrame, Frame, FrameDecoder, FrameType, Garbage,
                                       MetaAssembler, SeqTracker, decode_any_samples, decode_event, decode_json)
from pipeline.recording.schemas import CHANNELS, schema, validator
from pipeline.recording.writer import RecordingWriter

JOINT_STATE = "/robot/joint_state"
META_ACQUISITION = "robocal.acquisition"
MAX_LOGGED_PROBLEMS = 200


def strictly_increasing(t: np.ndarray, after: int | None) -> np.ndarray:
    """Smallest change making `t` strictly increasing (and > `after`): each value is raised
    to one ns past its predecessor where the clock mapping moved backwards."""
    if t.size == 0:
        return t
    k = np.arange(t.size, dtype=np.int64)
    base = t - k
    if after is not None:
        base = np.maximum(base, after + 1)
    return np.maximum.accumulate(base) + k


@dataclass
class Link:
    """State of one device link (role such as 'bridge', 'tracker', 'scanner')."""

    role: str
    port: str
    decoder: FrameDecoder = field(default_factory=FrameDecoder)
    seq: SeqTracker = field(default_factory=SeqTracker)
    clock: ClockSync = field(default_factory=ClockSync)
    hello: dict | None = None
    campaign: dict | None = None
    end: dict | None = None
    frames: int = 0
    samples: int = 0
    events: dict[str, int] = field(default_factory=dict)
    rejected: int = 0  # frames with a valid checksum but unusable content
    problems: list[dict] = field(default_factory=list)  # first MAX_LOGGED_PROBLEMS, with positions
    gaps: list[dict] = field(default_factory=list)
    connected: bool = False
    last_rx_ns: int = 0
    _d: list[int] = field(default_factory=list)
    _h: list[int] = field(default_factory=list)
    _samples: list[tuple[int, bytes, int]] = field(default_factory=list)  # (frame type, payload, host receive ns)
    _events: list[tuple[int, str, dict, int]] = field(default_factory=list)
    _last_t: int | None = None
    _unnamed: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]] = field(default_factory=list)
    drive: tuple[str, ...] | None = None  # DRIVE_FIELDS keys the stream carries, fixed by its first samples frame

    @property
    def errors(self) -> int:
        return self.decoder.bad_frames + self.seq.missing + self.rejected

    def log(self, kind: str, **kw) -> None:
        if len(self.problems) < MAX_LOGGED_PROBLEMS:
            self.problems.append({"kind": kind, **kw})

    def counts(self) -> dict:
        return {"frames": self.frames, "samples": self.samples, "events": dict(self.events),
                "missing_frames": self.seq.missing, "bad_frames": self.decoder.bad_frames,
                "garbage_bytes": self.decoder.garbage_bytes, "rejected_frames": self.rejected,
                "bytes": self.decoder.bytes_in,
                "drive_state": None if self.drive is None else [DRIVE_NAMES[DRIVE_FIELDS.index(k)] for k in self.drive],
                "last_seq": None if self.seq.expected is None else (self.seq.expected - 1) % (1 << 32)}


class Acquisition:
    """Turns device frames into a robocal recording."""

    def __init__(self, writer: RecordingWriter, links: dict[str, str], batch: int = 250):
        self.w = writer
        self.links = {role: Link(role, port) for role, port in links.items()}
        self.batch = batch
        self.meta = MetaAssembler()
        self.metadata_written: list[str] = []
        self.started_ns = time.time_ns()
        self._gap_k = 0

    # ----- input ----------------------------------------------------------------------------
    def on_bytes(self, role: str, data: bytes, host_ns: int) -> None:
        link = self.links[role]
        link.last_rx_ns = host_ns
        frames, problems = link.decoder.feed(data)
        for p in problems:
            if isinstance(p, BadFrame):
                link.log("bad_frame", offset=p.offset, reason=p.reason)
            elif isinstance(p, Garbage):
                link.log("garbage", offset=p.offset, bytes=p.n)
        for f in frames:
            self._frame(link, f, host_ns)

    def on_disconnect(self, role: str) -> None:
        link = self.links[role]
        for g in link.decoder.finish():
            link.log("garbage", offset=g.offset, bytes=g.n)

    def _frame(self, link: Link, f: Frame, host_ns: int) -> None:
        lost = link.seq.see(f.seq, f.offset)
        if lost:
            link.log("missing_frames", first_seq=link.seq.gaps[-1][0], count=lost, offset=f.offset)
        link.frames += 1
        link._d.append(f.device_time_ns)
        link._h.append(host_ns)
        t = f.type
        try:
            if t is FrameType.SAMPLES or t is FrameType.SAMPLES_DRIVE:
                link._samples.append((t, f.payload, host_ns))
            elif t is FrameType.EVENT:
                td, topic, body = decode_event(f.payload)
                if topic not in CHANNELS:
                    raise ValueError(f"unknown channel {topic!r}")
                link._events.append((td, topic, body, host_ns))
            elif t is FrameType.META:
                done = self.meta.add(f.payload)
                if done:
                    self.w.metadata(done[0], done[1])
                    self.metadata_written.append(done[0])
            elif t is FrameType.HELLO:
                if link.hello is None:
                    link.hello = decode_json(f.payload)
            elif t is FrameType.CAMPAIGN_START:
                if link.campaign is None:
                    link.campaign = decode_json(f.payload)
            elif t is FrameType.CAMPAIGN_END:
                if link.end is None:
                    link.end = decode_json(f.payload)
        except (ValueError, KeyError, UnicodeDecodeError) as e:
            link.rejected += 1
            link.log("rejected", seq=f.seq, offset=f.offset, reason=str(e))

    # ----- output ---------------------------------------------------------------------------
    def tick(self) -> None:
        """Map pending data to host time, write it, flush a complete chunk."""
        for link in self.links.values():
            if link._d:
                link.clock.add(np.array(link._d, np.int64), np.array(link._h, np.int64))
                link._d.clear()
                link._h.clear()
            fit = link.clock.fit()
            if fit is None:
                continue
            self._write_samples(link, fit)
            self._write_events(link, fit)
        self.w.flush_chunk()

    def _joint_names(self, link: Link, nj: int) -> list[str] | None:
        names = (link.hello or {}).get("joint_names")
        if names is not None and len(names) == nj:
            return list(names)
        return None

    def _write_samples(self, link: Link, fit) -> None:
        if link._samples:
            payloads = link._samples
            link._samples = []
            ts, qs, hs, ds = [], [], [], []
            for k, p, h in payloads:
                try:
                    t, q, d = decode_any_samples(k, p)
                    if link.drive is None:
                        link.drive = tuple(d)
                    elif tuple(d) != link.drive:  # the stream's fields are all present or all absent
                        raise ValueError(f"drive state {list(d) or 'none'} after frames with {list(link.drive) or 'none'}")
                except (ValueError, Exception) as e:  # struct.error is an Exception
                    link.rejected += 1
                    link.log("rejected", reason=f"{FrameType(k).name}: {e}")
                    continue
                ts.append(t)
                qs.append(q)
                hs.append(np.full(t.size, h, np.int64))
                ds.append(d)
            if ts:
                nj = {q.shape[1] for q in qs}
                if len(nj) > 1:
                    link.rejected += len(ts)
                    link.log("rejected", reason=f"SAMPLES with differing joint counts {sorted(nj)}")
                else:
                    t = np.concatenate(ts)
                    drive = {k: np.concatenate([d[k] for d in ds]) for k in link.drive}
                    link._unnamed.append((t, np.concatenate(qs), np.concatenate(hs), fit.to_host(t), drive))
        if not link._unnamed:
            return
        nj = link._unnamed[0][1].shape[1]
        names = self._joint_names(link, nj)
        if names is None:
            return  # held until the device's HELLO names the joints
        t_dev = np.concatenate([u[0] for u in link._unnamed])
        q = np.concatenate([u[1] for u in link._unnamed])
        h_rx = np.concatenate([u[2] for u in link._unnamed])
        t = np.concatenate([u[3] for u in link._unnamed])
        drive = {k: np.concatenate([u[4][k] for u in link._unnamed]) for k in link.drive or ()}
        link._unnamed.clear()
        t = strictly_increasing(t, link._last_t)
        link._last_t = int(t[-1])
        link.samples += t.size
        for s in range(0, t.size, self.batch):
            sl = slice(s, s + self.batch)
            self.w.write_batch(t[sl], q[sl], names, device_t_ns=t_dev[sl], host_t_ns=h_rx[sl],
                               **{k: v[sl] for k, v in drive.items()})

    def _write_events(self, link: Link, fit) -> None:
        if not link._events:
            return
        evs = link._events
        link._events = []
        corrected = fit.to_host(np.array([e[0] for e in evs], np.int64))
        for (td, topic, body, h), tc in zip(evs, corrected):
            stem = CHANNELS[topic]
            msg = dict(body)
            msg["timestamp_ns"] = int(tc)
            props = schema(stem).get("properties", {})
            if "device_timestamp_ns" in props or schema(stem).get("additionalProperties", True) is not False:
                msg["device_timestamp_ns"] = int(td)
            if "host_receive_ns" in props or schema(stem).get("additionalProperties", True) is not False:
                msg["host_receive_ns"] = int(h)
            errs = sorted(validator(stem).iter_errors(msg), key=str)
            if errs:
                link.rejected += 1
                link.log("rejected", topic=topic, reason=f"schema: {errs[0].message}")
                continue
            self.w.write(topic, msg)
            link.events[topic] = link.events.get(topic, 0) + 1

    # ----- gaps, summary --------------------------------------------------------------------
    def gap(self, role: str, start_ns: int, end_ns: int, reason: str) -> None:
        """A disconnect, logged in the recording as soon as the link is back."""
        link = self.links[role]
        g = {"device": role, "port": link.port, "start_ns": int(start_ns), "end_ns": int(end_ns),
             "duration_s": (end_ns - start_ns) / 1e9, "reason": reason}
        link.gaps.append(g)
        self.w.metadata(f"{META_ACQUISITION}.gap.{self._gap_k}", g)
        self._gap_k += 1

    def summary(self) -> dict:
        out: dict = {"started_ns": self.started_ns, "stopped_ns": time.time_ns(), "metadata": self.metadata_written,
                     "devices": {}}
        for role, link in self.links.items():
            fit = link.clock.fit()
            out["devices"][role] = {
                "port": link.port, "hello": link.hello, "campaign": link.campaign, "end": link.end,
                **link.counts(), "missing_ranges": [list(g) for g in link.seq.gaps[:20_000]],
                "clock": fit.as_dict() if fit else None, "gaps": link.gaps, "problems": link.problems}
        return out

    def finish(self, reason: str) -> dict:
        """Write what is pending and the acquisition summary; close the file."""
        for role in self.links:
            self.on_disconnect(role)
        self.tick()
        for link in self.links.values():  # joint names never announced: fall back to J1..Jn
            if link._unnamed:
                nj = link._unnamed[0][1].shape[1]
                link.hello = {**(link.hello or {}), "joint_names": [f"J{i + 1}" for i in range(nj)]}
                link.log("warning", reason="joint names never announced; wrote J1..Jn")
        self.tick()
        s = self.summary()
        s["stop_reason"] = reason
        self.w.metadata(META_ACQUISITION, s)
        self.w.close()
        return s

    def complete(self) -> bool:
        """The bridge (or the only device) has announced the end of its campaign."""
        bridge = self.links.get("bridge") or next(iter(self.links.values()))
        return bridge.end is not None
