"""A device process killed (or frozen) mid-run over a real pty pair is noticed
within 2 s, its gap is recorded, the port is retried with back-off, and a bridge that never
comes back stops the acquisition (which closes a valid recording)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import threading
import time

import pytest

from hostile_support import BUNDLED
from pipeline.recording.reader import read_recording
from stream_support import ROBOCAL, start_sim


def _reader(stream, lines: list[tuple[float, str]]) -> threading.Thread:
    def run():
        for line in iter(stream.readline, ""):
            lines.append((time.time(), line.rstrip()))
    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


@pytest.mark.parametrize("how", ["kill", "freeze"])
def test_a_dying_device_is_noticed_recorded_and_given_up_on(tmp_path, how):
    sim, devices = start_sim(tmp_path, "delta-tracker", "--recording", str(BUNDLED["delta-tracker"]), "--speed", "0.1")
    out = tmp_path / "acq.mcap"
    cmd = [ROBOCAL, "acquire", "--out", str(out), "--summary", str(tmp_path / "summary.json"),
           "--give-up-s", "3", "--max-s", "60"] + [a for r, p in devices.items() for a in ("--device", f"{r}={p}")]
    acq = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    lines: list[tuple[float, str]] = []
    t = _reader(acq.stderr, lines)
    try:
        deadline = time.time() + 60
        while time.time() < deadline and not any("bridge: " in ln for _, ln in lines):
            time.sleep(0.1)
        time.sleep(2.0)  # the campaign streams (at 0.1× it lasts ~4 min)
        assert acq.poll() is None, lines
        t_kill = time.time()
        os.kill(sim.pid, signal.SIGKILL if how == "kill" else signal.SIGSTOP)
        acq.wait(timeout=30)  # was still running 40 s later
        t.join(timeout=5)
    finally:
        if how == "freeze":
            os.kill(sim.pid, signal.SIGKILL)
        sim.wait(timeout=30)
        if acq.poll() is None:
            acq.kill()
    assert acq.returncode == 0, lines
    said = [(ts, ln) for ts, ln in lines if ts >= t_kill and ("gap" in ln and "reconnecting" in ln)]
    assert said and said[0][0] - t_kill < 2.0, [ln for ts, ln in lines if ts >= t_kill - 1]  # noticed within 2 s
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["stop_reason"].startswith("bridge gone"), summary["stop_reason"]
    gaps = summary["devices"]["bridge"]["gaps"]
    assert gaps and abs(gaps[0]["start_ns"] / 1e9 - t_kill) < 1.0 and gaps[0]["end_ns"] > gaps[0]["start_ns"]
    rec = read_recording(out)
    assert rec.complete and not rec.warnings
    recorded = [v for k, v in rec.metadata.items() if k.startswith("robocal.acquisition.gap.")]
    assert recorded and recorded[0]["device"] == "bridge" and "not reconnected" in recorded[0]["reason"]
    assert rec.messages.raw["/robot/joint_state"]  # what came before the death is kept
