"""Throughput of `robocal acquire`: a 1 kHz encoder stream (one sample per frame) plus contact
events over a real pty, and the same at 6.25 kHz for headroom.  Reports the acquire process's
steady-state CPU % (from /proc/PID/stat), frames/s, and losses (must be zero).

    .venv/bin/python benchmarks/bench_acquire.py
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROBOCAL = str(Path(sys.executable).parent / "robocal")
TICK = os.sysconf("SC_CLK_TCK")


def cpu_s(pid: int) -> float:
    f = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(f[11]) + int(f[12])) / TICK  # utime + stime


def run(tmp: Path, rec: Path, speed: float, label: str) -> dict:
    sim = subprocess.Popen([ROBOCAL, "device-sim", "arc-welder", "--recording", str(rec), "--speed", str(speed),
                            "--batch", "1", "--link-dir", str(tmp / f"dev{speed}")],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    port = sim.stdout.readline().split()[0].split("=", 1)[1]
    out, summ = tmp / f"acq{speed}.mcap", tmp / f"sum{speed}.json"
    acq = subprocess.Popen([ROBOCAL, "acquire", "--device", f"bridge={port}", "--out", str(out),
                            "--summary", str(summ)], stderr=subprocess.DEVNULL)
    time.sleep(3.0)  # start-up (imports) and the first seconds excluded
    c0, w0 = cpu_s(acq.pid), time.monotonic()
    time.sleep(8.0)
    c1, w1 = cpu_s(acq.pid), time.monotonic()
    acq.send_signal(signal.SIGINT)  # stop cleanly; the rest of the campaign is not needed
    acq.wait(timeout=60)
    sim.kill()
    sim.wait(timeout=60)
    s = json.loads(summ.read_text())["devices"]["bridge"]
    res = {"case": label, "sample_rate_hz": 250 * speed, "cpu_percent": 100 * (c1 - c0) / (w1 - w0),
           "frames": s["frames"], "samples": s["samples"], "events": sum(s["events"].values()),
           "missing_frames": s["missing_frames"], "bad_frames": s["bad_frames"],
           "file_mb": out.stat().st_size / 1e6}
    print(f"{label:>28}: {res['cpu_percent']:5.1f} % CPU of one core (steady state), {s['samples']} samples, "
          f"{res['events']} events, {s['missing_frames']} missing, {s['bad_frames']} bad, "
          f"{res['file_mb']:.1f} MB", flush=True)
    return res


def main() -> None:
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        rec = tmp / "campaign.mcap"
        subprocess.run([ROBOCAL, "simulate", "arc-welder", "--out", str(rec), "--contacts", "40", "--seed", "1"],
                       check=True, capture_output=True)
        results = [run(tmp, rec, 4.0, "1 kHz encoder + contacts"), run(tmp, rec, 25.0, "6.25 kHz encoder + contacts")]
    ok = all(r["missing_frames"] == 0 and r["bad_frames"] == 0 for r in results) and results[0]["cpu_percent"] < 50
    print(json.dumps({"bench": "acquire", "results": results, "ok": ok}))
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
