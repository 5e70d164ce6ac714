"""Benchmark: `robocal import ros2` on a long bag — N JointState messages and M measurements.

Run: .venv/bin/python benchmarks/bench_ros2_import.py [--hours 1] [--rate 100] [--storage mcap,sqlite3]
A 6R robot moves from stop to stop (2 s move, 2 s dwell, a PointStamped in the middle of each dwell:
900 measurements per hour), JointState at --rate Hz with 1e-5 rad encoder noise, written by rosbags'
own Writer.  Timed (best of --repeat): reading + CDR decoding + name matching (`read_bag` less the
pairing), the standstill pairing alone (`standstill.pair` on the same arrays), and writing the
recording (`write_urdf_recording`).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from pipeline.importers import standstill  # noqa: E402
from pipeline.importers.recording import write_urdf_recording  # noqa: E402
from pipeline.importers.ros2 import BagSpec, read_bag  # noqa: E402
from pipeline.models import urdf  # noqa: E402
from pipeline.simulate.ros2_bag import BagLayout, simulate_bag  # noqa: E402
from test_urdf_simulate import R6T  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--rate", type=float, default=100.0, help="JointState rate, Hz")
    ap.add_argument("--storage", default="mcap,sqlite3")
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args()
    desc = urdf.parse(R6T, "b", "tcp")
    layout = BagLayout(rate_hz=a.rate, noise_q_rad=1e-5)
    stops = int(round(a.hours * 3600 / (layout.move_s + layout.dwell_s)))
    print(f"bag: {a.hours:g} h of JointState at {a.rate:g} Hz, {stops} PointStamped measurements (6R robot)")
    for storage in a.storage.split(","):
        with tempfile.TemporaryDirectory() as d:
            t = time.perf_counter()
            truth = simulate_bag(Path(d) / "bag", desc, n=stops, seed=0, layout=layout, storage=storage)
            t_write_bag = time.perf_counter() - t
            size = truth["storage"].stat().st_size
            n = truth["n_joint_states"]
            best_read = best_pair = best_rec = np.inf
            for _ in range(a.repeat):
                t = time.perf_counter()
                table, extras = read_bag(Path(d) / "bag", desc, BagSpec(measure_topic="/tracker/point"))
                best_read = min(best_read, time.perf_counter() - t)
                tj = np.arange(n) / a.rate
                q = np.zeros((n, 6))
                tm = truth["t_meas_s"]
                t = time.perf_counter()
                standstill.pair(tj, q, tm)
                best_pair = min(best_pair, time.perf_counter() - t)
                t = time.perf_counter()
                write_urdf_recording(Path(d) / f"rec{_}.mcap", desc, "point", extras, table)
                best_rec = min(best_rec, time.perf_counter() - t)
            p = extras["ros2"]["pairing"]
            assert p["n_paired"] == stops, p
            total = best_read + best_rec
            print(f"{storage:8s} {n} joint states, {size / 1e6:.1f} MB bag (written in {t_write_bag:.1f} s): "
                  f"read + decode + pair {best_read:.2f} s ({n / (best_read - best_pair) / 1e3:.0f} k JointState/s), "
                  f"pairing alone {best_pair * 1e3:.1f} ms, recording written {best_rec:.2f} s, "
                  f"import total {total:.2f} s; {p['n_paired']} / {p['n_measurements']} paired")


if __name__ == "__main__":
    main()
