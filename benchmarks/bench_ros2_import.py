"""Benchmark: `robocal import ros2` on a long bag — N JointState messages and M measurements.

Run: .venv/bin/python benchmarks/bench_ros2_import.py [--hours 1] [--rate 100] [--storage mcap,sqlite3]
A 6R robot moves from stop to stop (2 s move, 2 s dwell, a PointStamped in the middle of each dwell:
900 measurements per hour), JointState at --rate Hz with 1e-5 rad encoder noise, written by rosbags'
own Writer.  The import is timed in a fresh process (best of --repeat; wall and CPU time, the box
being shared): reading + CDR decoding + name matching + pairing (`read_bag`), the standstill pairing
alone (`standstill.pair` on the same arrays), writing the recording (`write_urdf_recording`), and
the process's peak resident memory before and after the import.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from pipeline.importers import standstill  # noqa: E402
from pipeline.importers.recording import write_urdf_recording  # noqa: E402
from pipeline.ros2.points import BagSpec, read_bag  # noqa: E402
from pipeline.models import urdf  # noqa: E402
from pipeline.simulate.ros2_bag import BagLayout, simulate_bag  # noqa: E402
from test_urdf_simulate import R6T  # noqa: E402

DESC = urdf.parse(R6T, "b", "tcp")


def _status_mb(key: str) -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return float(line.split()[1]) / 1024
    return float("nan")


def import_only(bag: Path, repeat: int, out: Path) -> dict:
    """Time the import of `bag` in this process; its resident memory before, and the peak during
    the imports (Linux: the high-water mark is reset first through /proc/self/clear_refs)."""
    import gc

    gc.collect()
    rss0 = _status_mb("VmRSS")
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        pass
    best = {"read_s": np.inf, "read_cpu_s": np.inf, "pair_s": np.inf, "write_s": np.inf}
    for k in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        table, extras = read_bag(bag, DESC, BagSpec(measure_topic="/tracker/point"))
        best["read_s"] = min(best["read_s"], time.perf_counter() - t)
        best["read_cpu_s"] = min(best["read_cpu_s"], time.process_time() - c)
        n = extras["ros2"]["joint_states"]["n_used"]
        tj, q = np.arange(n) / 100.0, np.zeros((n, 6))
        tm = np.sort(np.random.default_rng(0).uniform(0, n / 100.0, extras["ros2"]["pairing"]["n_measurements"]))
        t = time.perf_counter()
        standstill.pair(tj, q, tm)
        best["pair_s"] = min(best["pair_s"], time.perf_counter() - t)
        t = time.perf_counter()
        write_urdf_recording(out.with_name(f"{out.stem}{k}.mcap"), DESC, "point", extras, table)
        best["write_s"] = min(best["write_s"], time.perf_counter() - t)
    p = extras["ros2"]["pairing"]
    return {**best, "n": n, "paired": p["n_paired"], "measurements": p["n_measurements"], "rss_before_mb": rss0,
            "rss_peak_mb": _status_mb("VmHWM")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--rate", type=float, default=100.0, help="JointState rate, Hz")
    ap.add_argument("--storage", default="mcap,sqlite3")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--import-only", type=Path, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.import_only:
        print(json.dumps(import_only(a.import_only, a.repeat, a.import_only.parent / "rec.mcap")))
        return
    layout = BagLayout(rate_hz=a.rate, noise_q_rad=1e-5)
    stops = int(round(a.hours * 3600 / (layout.move_s + layout.dwell_s)))
    print(f"bag: {a.hours:g} h of JointState at {a.rate:g} Hz, {stops} PointStamped measurements (6R robot)")
    for storage in a.storage.split(","):
        with tempfile.TemporaryDirectory() as d:
            t = time.perf_counter()
            truth = simulate_bag(Path(d) / "bag", DESC, n=stops, seed=0, layout=layout, storage=storage)
            t_write = time.perf_counter() - t
            size = truth["storage"].stat().st_size
            proc = subprocess.run([sys.executable, __file__, "--import-only", str(Path(d) / "bag"),
                                   "--repeat", str(a.repeat)], capture_output=True, text=True, check=True)
            r = json.loads(proc.stdout.strip().splitlines()[-1])
            assert r["paired"] == stops, r
            print(f"{storage:8s} {r['n']} joint states, {size / 1e6:.1f} MB bag (written in {t_write:.1f} s): "
                  f"read + decode + pair {r['read_s']:.2f} s wall, {r['read_cpu_s']:.2f} s CPU "
                  f"({r['n'] / r['read_cpu_s'] / 1e3:.0f} k JointState/s of CPU); pairing alone "
                  f"{r['pair_s'] * 1e3:.1f} ms; recording written {r['write_s']:.2f} s; peak memory "
                  f"{r['rss_peak_mb']:.0f} MB ({r['rss_before_mb']:.0f} MB resident before the import); "
                  f"{r['paired']} / {r['measurements']} paired")


if __name__ == "__main__":
    main()
