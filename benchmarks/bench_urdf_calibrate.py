"""Calibration speed of a 7-joint URDF robot with 3-D points (laser tracker): solve time (rank
test + Levenberg–Marquardt, the whole 61-parameter joint-origin model) at 1 000 / 10 000 /
100 000 poses.  Target: < 0.2 s at 1 000 poses, cost linear in poses.

    python benchmarks/bench_urdf_calibrate.py [--poses 1000,10000,100000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from pipeline.identify.least_squares import FitOptions, fit
from pipeline.measurements.point import PointModel
from pipeline.models import urdf, urdf_arm
from pipeline.simulate.urdf_robot import campaign, random_truth

_REAL = Path(__file__).resolve().parents[2] / "shared" / "real-data"  # ../shared/real-data of the checkout
PANDA = _REAL / "mukca_panda" / "urdf" / "panda.urdf"


def robot() -> urdf_arm.UrdfArm:
    if PANDA.is_file():
        print(f"arm: Panda ({PANDA})")
        return urdf_arm.UrdfArm(urdf.read(PANDA, "panda_link0", "ball_link"))
    print("arm: the tests' prismatic + 6R arm (the Panda URDF is missing)")
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from test_urdf_simulate import PR6  # a prismatic torso + 6R arm: 7 joints

    return urdf_arm.UrdfArm(urdf.parse(PR6, "base", "flange"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--poses", default="1000,10000,100000")
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    arm = robot()
    model = PointModel(arm)
    rng = np.random.default_rng(0)
    truth = random_truth(model, rng, 1e-3, 3e-3)
    print(f"robot: {arm.desc.name}, {arm.n_joints} joints, {len(model.parameter_names())} parameters")
    print("| poses | solve (best of repeats) | per pose | identified | RMS after (noise 0.02 mm) |")
    print("|---|---|---|---|---|")
    for n in map(int, a.poses.split(",")):
        table, _ = campaign(model, truth, n, 1, "point", noise_m=2e-5)
        best = np.inf
        for _ in range(a.repeat):
            t0 = time.perf_counter()
            f = fit(model, table, FitOptions(before=False))
            best = min(best, time.perf_counter() - t0)
        print(f"| {n} | {best:.3f} s | {best / n * 1e6:.1f} µs | {int(f.free.sum())}/{len(f.names)} | "
              f"{f.rms_after * 1e3:.4f} mm |", flush=True)


if __name__ == "__main__":
    main()
