"""Shared helpers of the encoder-stream and acquisition tests: bit patterns of float arrays, and the
acquisition run over real pseudo-terminals (`robocal device-sim` → `robocal acquire`, both real
processes)."""

from __future__ import annotations

import json
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROBOCAL = str(Path(sys.executable).parent / "robocal")


def bits(a: np.ndarray) -> np.ndarray:
    """The float64 values' bit patterns (int64): equal only when bit for bit equal (NaN payloads, ±0)."""
    return np.ascontiguousarray(a, np.float64).view(np.int64)


def expected_devices(system: str, args) -> int:
    return {"arc-welder": 1, "urdf": 1}.get(system, 2)


def start_sim(tmp: Path, system: str, *args: str) -> tuple[subprocess.Popen, dict[str, str]]:
    """Start `robocal device-sim` (report to tmp/sim.json); returns the process and its ROLE=PATH announcements."""
    proc = subprocess.Popen([ROBOCAL, "device-sim", system, "--link-dir", str(tmp / "dev"),
                             "--report", str(tmp / "sim.json"), "--wait", "60", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    devices: dict[str, str] = {}
    lines: queue.Queue[str] = queue.Queue()  # read in a thread: a silent device-sim cannot block past the deadline

    def pump() -> None:  # (and it keeps draining stdout afterwards: the pipe never fills)
        for line in iter(proc.stdout.readline, ""):
            lines.put(line)
        lines.put("")

    threading.Thread(target=pump, daemon=True).start()
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline:
            try:
                line = lines.get(timeout=max(deadline - time.monotonic(), 0.01))
            except queue.Empty:
                break
            if not line:
                raise AssertionError(f"device-sim exited: {proc.stderr.read()}")
            role, _, rest = line.partition("=")
            devices[role] = rest.split()[0]
            assert Path(rest.split()[1]).is_char_device()  # a real tty
            if len(devices) == expected_devices(system, args):
                return proc, devices
        raise AssertionError("device-sim did not announce its ports within 60 s")
    except BaseException:  # any failure here: no device-sim left running
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=30)
        raise


def acquire(tmp: Path, devices: dict[str, str], out: Path, *extra: str, timeout: float = 120) -> dict:
    """Run `robocal acquire` to its end (exit 0 asserted); its summary (tmp/summary.json)."""
    cmd = [ROBOCAL, "acquire", "--out", str(out), "--summary", str(tmp / "summary.json"), *extra]
    for role, path in devices.items():
        cmd += ["--device", f"{role}={path}"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    assert r.returncode == 0, r.stderr
    return json.loads((tmp / "summary.json").read_text())


def finish_sim(proc: subprocess.Popen, tmp: Path) -> dict:
    """Wait for device-sim (exit 0 asserted); its report (tmp/sim.json)."""
    proc.wait(timeout=60)
    assert proc.returncode == 0, proc.stderr.read()
    return json.loads((tmp / "sim.json").read_text())


def record_over_pty(tmp: Path, system: str, sim_args: tuple[str, ...] | list[str], *acquire_args: str
                    ) -> tuple[Path, dict, dict]:
    """The whole run: device-sim SYSTEM `sim_args` → acquire into tmp/acq.mcap (`acquire_args`) → wait.
    Returns (recording, acquire summary, device-sim report); the device process is killed on failure."""
    proc, devices = start_sim(tmp, system, *sim_args)
    out = tmp / "acq.mcap"
    try:
        summary = acquire(tmp, devices, out, *acquire_args)
        report = finish_sim(proc, tmp)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=30)
    return out, summary, report


def simulate(tmp: Path, system: str, args: list[str]) -> Path:
    """`robocal simulate SYSTEM args` into tmp/SYSTEM.direct.mcap."""
    out = tmp / f"{system}.direct.mcap"
    subprocess.run([ROBOCAL, "simulate", system, "--out", str(out), *args], check=True, capture_output=True)
    return out
