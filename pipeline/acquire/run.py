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
SILENCE_S = 1.5  # a device that sent bytes and then nothing for this long is gone (devices announce every 1 s)
GIVE_UP_S = 30.0  # the bridge down this long: stop and close the recording (0: retry for ever)


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
    heard: bool = False  # bytes received since this connection opened
    heard_ever: bool = False
    down: bool = False  # a gap is open (since down_since_ns, for `reason`) until bytes arrive again
    opened_ns: int = 0


def _open(p: Port) -> None:
    s = serial.Serial()
    s.port = os.path.realpath(p.path)  # a by-id style symlink may point elsewhere after a reconnect
    s.baudrate = 3_000_000  # ignored by ptys and USB-CDC bridges
    s.timeout = 0
    s.open()
    p.ser = s


def acquire(devices: dict[str, str], out: Path, *, max_s: float | None = None, connect_timeout_s: float = 10.0,
            end_grace_s: float = 1.0, fsync: bool = False, status: Callable[[str], None] | None = None,
            log: Callable[[str], None] = print, silence_s: float = SILENCE_S, give_up_s: float = GIVE_UP_S) -> dict:
    """Record `devices` ({role: port}) into `out` until stopped (SIGINT/SIGTERM), until the
    bridge's campaign is complete, or `max_s`.  Returns the acquisition summary.

    A port that fails, reaches end of file, or falls silent for `silence_s` after sending is
    closed at once (said in `log`), its gap recorded from the last byte received, and reopened
    with back-off; a bridge down for `give_up_s` (0: never) stops the acquisition."""
    if "bridge" not in devices:
        raise RobocalError("acquire needs a controller bridge: --device bridge=PORT")
    from pipeline.recording.output import ACQUIRED, check_output

    check_output(out, force=None)  # before anything changes: no folder made, signal handlers untouched
    out.parent.mkdir(parents=True, exist_ok=True)
    stop = {"why": ""}

    def on_signal(signum, _frame):
        stop["why"] = signal.Signals(signum).name

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    ports = {role: Port(role, path) for role, path in devices.items()}
    sel = selectors.DefaultSelector()
    f = open(out, "wb")
    writer = RecordingWriter(f, scene=True, origin=ACQUIRED)  # /tf and /robot_description added at close (recording.scene)
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
                    p.ever_open, p.heard, p.opened_ns = True, False, time.time_ns()
                    p.backoff_s = BACKOFF_S[0] if not p.down else min(2 * p.backoff_s, BACKOFF_S[1])
            h = time.time_ns()
            for p in ports.values():
                link = acq.links[p.role]
                if link.end is not None:
                    continue
                quiet_from = link.last_rx_ns if p.heard else p.opened_ns
                if p.ser is not None and p.heard_ever and h - quiet_from > silence_s * 1e9:
                    _down(p, acq, sel, quiet_from, f"silent for {(h - quiet_from) / 1e9:.1f} s" if p.heard
                          else "no data since reopening", log)
                if p.down and p.role == "bridge" and give_up_s > 0 and h - p.down_since_ns > give_up_s * 1e9:
                    stop["why"] = f"bridge gone: no data for {(h - p.down_since_ns) / 1e9:.0f} s ({p.reason})"
            for key, _ in sel.select(timeout=0.02):
                p: Port = key.data
                reason = ""
                try:
                    data = p.ser.read(1 << 16)
                except (serial.SerialException, OSError) as e:
                    data, reason = b"", f"disconnected: {e}"
                h = time.time_ns()
                if data:
                    if p.down:  # back: the gap ends at its first byte
                        acq.gap(p.role, p.down_since_ns, h, p.reason)
                        log(f"{p.role}: reconnected to {p.path} after {(h - p.down_since_ns) / 1e9:.2f} s")
                        p.down, p.reason, p.backoff_s = False, "", BACKOFF_S[0]
                    acq.on_bytes(p.role, data, h)
                    p.heard = p.heard_ever = True
                if reason:
                    last = acq.links[p.role].last_rx_ns
                    _down(p, acq, sel, last if p.heard and last else h, reason, log)
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
            if p.down and acq.links[p.role].end is None:  # still down: the gap runs to the end
                acq.gap(p.role, p.down_since_ns, time.time_ns(), f"{p.reason} (not reconnected)")
        summary = acq.finish(stop["why"] or "error")
        f.close()
    return summary


def _down(p: Port, acq: Acquisition, sel: selectors.BaseSelector, since_ns: int, reason: str,
          log: Callable[[str], None]) -> None:
    """Close a dead or silent port and retry it with back-off; a new gap starts at `since_ns`
    (the last byte received), said once."""
    sel.unregister(p.ser.fileno())
    p.ser.close()
    p.ser = None
    p.next_try = time.monotonic() + p.backoff_s
    acq.on_disconnect(p.role)
    acq.links[p.role].connected = False
    if not p.down:
        p.down, p.down_since_ns, p.reason = True, since_ns, reason
        if acq.links[p.role].end is None:
            log(f"{p.role}: {reason}; gap recorded from {since_ns / 1e9:.3f} s (host clock), reconnecting with back-off")


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
