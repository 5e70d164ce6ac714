"""Acquisition shell: serial ports (pyserial), signals, the flush cadence, back-off on disconnect."""

from __future__ import annotations

import os
import selectors
import signal
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import serial

from pipeline.acquire.session import Acquisition
from pipeline.errors import RobocalError
from pipeline.recording.writer import RecordingWriter

FLUSH_S = 0.5  # data reaches a flushed, complete chunk within ~2 × this
BACKOFF_S = (0.1, 2.0)  # first and largest wait between reconnection attempts


@dataclass
class Port:
    role: str
    path: str
    ser: serial.Serial | None = None
    backoff_s: float = BACKOFF_S[0]
    next_try: float = 0.0
    down_since_ns: int = 0
    ever_open: bool = False
    reason: str = ""


def _open(p: Port) -> None:
    s = serial.Serial()
    s.port = os.path.realpath(p.path)  # a by-id style symlink may point elsewhere after a reconnect
    s.baudrate = 3_000_000  # ignored by ptys and USB-CDC bridges
    s.timeout = 0
    s.open()
    p.ser = s


def acquire(devices: dict[str, str], out: Path, *, max_s: float | None = None, connect_timeout_s: float = 10.0,
            end_grace_s: float = 1.0, fsync: bool = False, status: Callable[[str], None] | None = None,
            log: Callable[[str], None] = print) -> dict:
    """Record `devices` ({role: port}) into `out` until stopped (SIGINT/SIGTERM), until the
    bridge's campaign is complete, or `max_s`.  Returns the acquisition summary."""
    if "bridge" not in devices:
        raise RobocalError("acquire needs a controller bridge: --device bridge=PORT")
    out.parent.mkdir(parents=True, exist_ok=True)
    stop = {"why": ""}

    def on_signal(signum, _frame):
        stop["why"] = signal.Signals(signum).name

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    ports = {role: Port(role, path) for role, path in devices.items()}
    sel = selectors.DefaultSelector()
    f = open(out, "wb")
    writer = RecordingWriter(f)
    acq = Acquisition(writer, devices)
    t_start = time.monotonic()
    next_flush = t_start + FLUSH_S
    next_status = t_start
    ended_at = None
    try:
        while not stop["why"]:
            now = time.monotonic()
            for p in ports.values():
                if p.ser is None and now >= p.next_try:
                    try:
                        _open(p)
                    except (serial.SerialException, OSError) as e:
                        p.reason = p.reason or str(e)
                        p.next_try = now + p.backoff_s
                        p.backoff_s = min(2 * p.backoff_s, BACKOFF_S[1])
                        if not p.ever_open and now - t_start > connect_timeout_s:
                            raise RobocalError(f"{p.role}: cannot open {p.path}: {e}") from None
                        continue
                    sel.register(p.ser.fileno(), selectors.EVENT_READ, p)
                    acq.links[p.role].connected = True
                    if p.ever_open:
                        acq.gap(p.role, p.down_since_ns, time.time_ns(), p.reason)
                        log(f"{p.role}: reconnected to {p.path} after "
                            f"{(time.time_ns() - p.down_since_ns) / 1e9:.2f} s")
                    p.ever_open, p.backoff_s, p.reason = True, BACKOFF_S[0], ""
            for key, _ in sel.select(timeout=0.02):
                p: Port = key.data
                try:
                    data = p.ser.read(1 << 16)
                except (serial.SerialException, OSError) as e:
                    data, p.reason = b"", f"disconnected: {e}"
                h = time.time_ns()
                if data:
                    acq.on_bytes(p.role, data, h)
                if p.reason:
                    sel.unregister(key.fd)
                    p.ser.close()
                    p.ser, p.down_since_ns = None, h
                    p.next_try = time.monotonic() + p.backoff_s
                    acq.on_disconnect(p.role)
                    acq.links[p.role].connected = False
                    if acq.links[p.role].end is None:
                        log(f"{p.role}: {p.reason}; retrying with back-off")
            now = time.monotonic()
            if now >= next_flush:
                acq.tick()
                if fsync:
                    os.fsync(f.fileno())
                next_flush = now + FLUSH_S
            if status and now >= next_status:
                status(status_line(acq))
                next_status = now + 0.25
            if acq.complete():
                ended_at = ended_at or now
                others_done = all(link.end is not None or not link.connected for link in acq.links.values())
                if others_done or now - ended_at > end_grace_s:
                    stop["why"] = "campaign complete"
            if max_s is not None and now - t_start > max_s:
                stop["why"] = f"time limit {max_s} s"
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        for p in ports.values():
            if p.ser is not None:
                p.ser.close()
        summary = acq.finish(stop["why"] or "error")
        f.close()
    return summary


def status_line(acq: Acquisition) -> str:
    parts = []
    for role, link in acq.links.items():
        ev = sum(link.events.values())
        exp = (link.campaign or {}).get("expected", {})
        n_exp = exp.get("/robot/joint_state")
        s = f"{role}: {link.samples}{'/' + str(n_exp) if n_exp else ''} samples, {ev} events, " \
            f"{link.errors} errors ({link.decoder.bad_frames} bad, {link.seq.missing} missing)"
        if not link.connected:
            s += " [disconnected]"
        parts.append(s)
    return " | ".join(parts)
