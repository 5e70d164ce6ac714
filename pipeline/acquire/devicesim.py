"""Virtual devices: play a recorded or simulated campaign over pseudo-terminals.

Core (pure): `device_streams` turns a recording into each device's frames, in send order,
with the device's own clock; `impair` damages one frame's bytes.  Shell: `Player` opens one
pty per device (raw mode, a stable symlink per device, as udev's /dev/serial/by-id does),
waits for the host to open it, and writes the frames at `speed` × real time, with optional
line noise, dropped bytes and disconnects.
"""

from __future__ import annotations

import json
import os
import select
import time
import tty
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.acquire import protocol as P
from pipeline.ingest.streams import joint_stream
from pipeline.recording.scene import SCENE_CHANNELS
from pipeline.recording.reader import Recording
from pipeline.recording.schemas import META_CAMPAIGN

# which device delivers a channel's measurements
CHANNEL_DEVICE = {"/touch/contact": "bridge", "/tracker/point": "tracker", "/scanner/stripe": "scanner"}
JOINT_STATE = "/robot/joint_state"


@dataclass(frozen=True)
class Clock:
    """Device clock: d = t + offset + drift · (t − t0), all ns (t the campaign's true time)."""

    t0: int
    offset_ns: int = 0
    drift: float = 0.0  # 1e-4 = 100 ppm

    def __call__(self, t_ns: np.ndarray | int) -> np.ndarray:
        t = np.asarray(t_ns, dtype=np.int64)
        return t + self.offset_ns + np.round((t - self.t0) * self.drift).astype(np.int64)


@dataclass
class DeviceStream:
    """One device's frames in send order: true send times (ns), frame bytes, their seqs."""

    role: str
    t_ns: np.ndarray
    frames: list[bytes]
    kinds: list[int]
    samples: int = 0
    events: int = 0


def device_streams(rec: Recording, clock: Clock, batch: int = 1, announce_every_s: float = 1.0,
                   heartbeat_s: float = 0.1) -> dict[str, DeviceStream]:
    """Every device's frames for the campaign in `rec` (see docs/guide/acquire.md)."""
    js = joint_stream(rec)
    t_all = [js.t_ns[0]]
    events: dict[str, list[tuple[int, str, dict]]] = {}
    for topic in list(rec.messages.raw):
        if topic == JOINT_STATE or not rec.messages.raw[topic] or topic in SCENE_CHANNELS:
            continue  # /tf, /robot_description: derived by the writer, not sent by any device
        msgs = rec.messages[topic]
        role = CHANNEL_DEVICE.get(topic, "bridge")
        for m in msgs:
            body = {k: v for k, v in m.items() if k not in ("timestamp_ns", "device_timestamp_ns", "host_receive_ns")}
            events.setdefault(role, []).append((int(m["timestamp_ns"]), topic, body))
            t_all.append(int(m["timestamp_ns"]))
    t_start, t_end = int(min(t_all)), int(max(max(t_all), js.t_ns[-1]))
    system = rec.metadata.get(META_CAMPAIGN, {}).get("system", "")
    roles = ["bridge", *sorted(r for r in events if r != "bridge")]
    meta_parts = [p for name, doc in rec.metadata.items() if name.startswith("robocal.")
                  and not name.startswith("robocal.acquisition")
                  for p in P.encode_meta_parts(name, json.dumps(doc, separators=(",", ":")), part_size=96)]
    out = {}
    for role in roles:
        items: list[tuple[int, int, int, bytes]] = []  # (t, order, kind, payload)
        evs = events.get(role, [])
        hello = {"device": role, "protocol": P.VERSION, "system": system,
                 "channels": sorted({e[1] for e in evs}) + ([JOINT_STATE] if role == "bridge" else [])}
        drive = {k: getattr(js, k) for k in P.DRIVE_FIELDS if getattr(js, k) is not None}
        if role == "bridge":
            hello["joint_names"] = list(js.names)
            if drive:
                hello["drive_state"] = [P.DRIVE_NAMES[P.DRIVE_FIELDS.index(k)] for k in drive]
        announce = [(P.FrameType.HELLO, P.encode_json(hello))]
        if role == "bridge":
            counts = {JOINT_STATE: int(js.t_ns.size)}
            for r_evs in events.values():
                for _, topic, _ in r_evs:
                    counts[topic] = counts.get(topic, 0) + 1
            announce.append((P.FrameType.CAMPAIGN_START, P.encode_json(
                {"system": system, "expected": counts, "duration_s": (t_end - t_start) / 1e9})))
            announce += [(P.FrameType.META, p) for p in meta_parts]
        for ta in np.arange(t_start, t_end, int(announce_every_s * 1e9)) if announce_every_s > 0 else [t_start]:
            items += [(int(ta), 0, k, p) for k, p in announce]
        n_samples = 0
        if role == "bridge":
            d = clock(js.t_ns)
            per = min(batch, P.max_drive_samples(js.q.shape[1], len(drive))) if drive else batch
            for s in range(0, js.t_ns.size, per):
                sl = slice(s, s + per)
                if drive:  # the drive state rides in SAMPLES_DRIVE; without it, plain SAMPLES as before
                    kind, payload = P.FrameType.SAMPLES_DRIVE, P.encode_samples_drive(
                        d[sl], js.q[sl], {k: v[sl] for k, v in drive.items()})
                else:
                    kind, payload = P.FrameType.SAMPLES, P.encode_samples(d[sl], js.q[sl])
                items.append((int(js.t_ns[sl][-1]), 1, kind, payload))
            n_samples = int(js.t_ns.size)
        else:
            items += [(int(t), 2, P.FrameType.HEARTBEAT, b"")
                      for t in np.arange(t_start, t_end, int(heartbeat_s * 1e9))]
        for t, topic, body in evs:
            items.append((t, 1, P.FrameType.EVENT, P.encode_event(int(clock(t)), topic, body)))
        items.sort(key=lambda it: (it[0], it[1]))
        end = P.encode_json({"samples": n_samples, "events": len(evs), "frames": len(items) + 8})
        items += [(t_end, 3, P.FrameType.CAMPAIGN_END, end)] * 8  # repeated: it ends the recording
        t = np.array([it[0] for it in items], np.int64)
        d_send = clock(t)
        frames = [P.encode_frame(k, seq, int(ds), p) for seq, ((_, _, k, p), ds) in enumerate(zip(items, d_send))]
        out[role] = DeviceStream(role, t, frames, [int(it[2]) for it in items], n_samples, len(evs))
    return out


def impair(frame: bytes, rng: np.random.Generator, corrupt_p: float, drop_p: float,
           noise_p: float) -> tuple[bytes, bool]:
    """Damage a frame's bytes: each byte flipped with probability `corrupt_p` or dropped with
    `drop_p`; with probability `noise_p` a burst of 1–32 random bytes (line noise) is put
    before the frame (the frame itself stays intact).  Returns (bytes, frame damaged)."""
    b = np.frombuffer(frame, np.uint8)
    damaged = False
    if corrupt_p > 0:
        m = rng.random(b.size) < corrupt_p
        if m.any():
            b = b.copy()
            b[m] ^= rng.integers(1, 256, int(m.sum()), dtype=np.uint8)
            damaged = True
    if drop_p > 0:
        keep = rng.random(b.size) >= drop_p
        if not keep.all():
            b = b[keep]
            damaged = True
    out = b.tobytes()
    if noise_p > 0 and rng.random() < noise_p:
        out = rng.integers(0, 256, int(rng.integers(1, 33)), dtype=np.uint8).tobytes() + out
    return out, damaged


# ----- shell: ptys ------------------------------------------------------------------------------
@dataclass
class Pty:
    """A pseudo-terminal whose slave the host opens through the symlink `link`."""

    link: Path
    master: int = -1
    tty_path: str = ""
    host_seen: bool = False

    def open(self) -> None:
        m, s = os.openpty()
        tty.setraw(s)  # no echo, no line discipline: bytes pass unchanged
        self.tty_path = os.ttyname(s)
        os.close(s)  # the master reports POLLHUP until the host opens the slave
        os.set_blocking(m, False)
        self.master = m
        self.host_seen = False
        tmp = self.link.with_name(self.link.name + ".tmp")
        tmp.unlink(missing_ok=True)
        tmp.symlink_to(self.tty_path)
        os.replace(tmp, self.link)

    def host_open(self) -> bool:
        """The host has the slave open (no hang-up on the master)."""
        if self.master < 0:
            return False
        p = select.poll()
        p.register(self.master, select.POLLOUT)
        ev = p.poll(0)
        up = not (ev and ev[0][1] & select.POLLHUP)  # no event at all: buffer full, host still there
        self.host_seen |= up
        return up

    def write(self, data: bytes) -> bool:
        """Write all of `data`, waiting while the host is slow (flow control); False if the
        host hung up (nobody has the port open), the rest of `data` then being lost."""
        view = memoryview(data)
        while view:
            try:
                view = view[os.write(self.master, view):]
            except BlockingIOError:
                if not self.host_open():
                    return False
                select.select([], [self.master], [], 0.05)
        return True

    def drain(self) -> None:
        """Discard whatever the host sent (nothing, in protocol v1)."""
        try:
            while os.read(self.master, 4096):
                pass
        except (BlockingIOError, OSError):
            pass

    def close(self) -> None:
        """Unplug: the symlink goes first (as udev removes /dev/serial/by-id links), so a
        host retrying never opens a recycled /dev/pts number that now belongs to another pty."""
        self.link.unlink(missing_ok=True)
        if self.master >= 0:
            os.close(self.master)
            self.master = -1


@dataclass
class Impairments:
    corrupt_p: float = 0.0
    drop_p: float = 0.0
    noise_p: float = 0.0
    disconnect_every_s: float = 0.0  # wall seconds between disconnects of `disconnect_device` (0: never)
    disconnect_for_s: float = 1.0
    disconnect_device: str = "bridge"
    seed: int = 0


@dataclass
class PlayReport:
    devices: dict[str, dict] = field(default_factory=dict)
    wall_start_ns: int = 0
    sim_start_ns: int = 0
    speed: float = 1.0


def play(streams: dict[str, DeviceStream], link_dir: Path, speed: float = 1.0, imp: Impairments = Impairments(),
         wait_s: float = 60.0, linger_s: float = 2.0, announce=print, clock: Clock | None = None) -> PlayReport:
    """Open the ptys, wait for the host, play every frame at `speed` × real time."""
    rng = np.random.default_rng(imp.seed)
    link_dir.mkdir(parents=True, exist_ok=True)
    ptys = {role: Pty(link_dir / role) for role in streams}
    for role, p in ptys.items():
        p.open()
        announce(f"{role}={p.link} {p.tty_path}")
    deadline = time.monotonic() + wait_s
    while not all(p.host_open() for p in ptys.values()):
        if time.monotonic() > deadline:
            raise TimeoutError(f"no host opened {', '.join(str(p.link) for p in ptys.values() if not p.host_seen)} "
                               f"within {wait_s} s")
        time.sleep(0.01)
    time.sleep(0.2)  # let pyserial finish opening (it flushes its input buffer on open)

    roles = list(streams)
    t = np.concatenate([streams[r].t_ns for r in roles])
    who = np.concatenate([np.full(streams[r].t_ns.size, i) for i, r in enumerate(roles)])
    idx = np.concatenate([np.arange(streams[r].t_ns.size) for r in roles])
    order = np.argsort(t, kind="stable")
    t, who, idx = t[order], who[order], idx[order]
    rep = PlayReport(speed=speed, sim_start_ns=int(t[0]))
    for r in roles:
        rep.devices[r] = {"frames": len(streams[r].frames), "sent": 0, "damaged_seqs": [], "lost_seqs": [],
                          "samples": streams[r].samples, "events": streams[r].events, "disconnects": []}
    wall0 = time.monotonic()
    rep.wall_start_ns = time.time_ns()
    next_disc = wall0 + imp.disconnect_every_s if imp.disconnect_every_s > 0 else float("inf")
    down_until = 0.0
    i, n = 0, t.size
    while i < n:
        now = time.monotonic()
        left_s = (t[-1] - t[0]) / speed / 1e9 - (now - wall0)
        if now >= next_disc and left_s < imp.disconnect_for_s + 1.0:
            next_disc = float("inf")  # no unplugging at the very end: the campaign end must get through
        if now >= next_disc and imp.disconnect_device in ptys:
            p = ptys[imp.disconnect_device]
            p.close()
            down_until = now + imp.disconnect_for_s
            next_disc = down_until + imp.disconnect_every_s
            rep.devices[imp.disconnect_device]["disconnects"].append([time.time_ns(), None])
        if down_until and now >= down_until:
            p = ptys[imp.disconnect_device]
            p.open()
            announce(f"{imp.disconnect_device}={p.link} {p.tty_path} (reconnected)")
            w_end = time.monotonic() + wait_s
            while not p.host_open() and time.monotonic() < w_end:
                time.sleep(0.01)
            time.sleep(0.2)
            rep.devices[imp.disconnect_device]["disconnects"][-1][1] = time.time_ns()
            down_until = 0.0
        due = t[0] + (now - wall0) * speed * 1e9
        j = int(np.searchsorted(t, due, side="right"))
        if j == i:
            time.sleep(min(0.005, max(0.0, (t[i] - due) / speed / 1e9)))
            continue
        out: dict[int, list[bytes]] = {}
        for k in range(i, j):
            w, f = int(who[k]), int(idx[k])
            role = roles[w]
            if down_until and role == imp.disconnect_device:
                rep.devices[role]["lost_seqs"].append(f)
                continue
            b, bad = impair(streams[role].frames[f], rng, imp.corrupt_p, imp.drop_p, imp.noise_p)
            if bad:
                rep.devices[role]["damaged_seqs"].append(f)
            out.setdefault(w, []).append(b)
            rep.devices[role]["sent"] += 1
        for w, bs in out.items():
            p = ptys[roles[w]]
            p.drain()
            if not p.write(b"".join(bs)):
                rep.devices[roles[w]]["unconfirmed_after_seq"] = int(idx[j - 1])
        i = j
    end = time.monotonic() + linger_s
    while time.monotonic() < end and any(p.host_open() for p in ptys.values()):
        time.sleep(0.02)
    for p in ptys.values():
        p.close()
        p.link.unlink(missing_ok=True)
    return rep
