"""Camera calibration speed: N images (default 100) of a 9×6 chessboard, 640×480, rendered from a
simulated 6R arm (eye-in-hand; `pipeline.simulate.camera_images`, not timed), then timed:

* detection: `robocal import images` (process pool, `--workers`, default the CPU count), which
  also writes the recording;
  with ``--ros2``: the same images in a ROS 2 bag (mono8 Image + CameraInfo + JointState at 50 Hz,
  written with rosbags' Writer, not timed) read by `robocal import ros2 --target` (two passes over
  the bag, CDR decoding, standstill pairing, the same detection pool);
* calibration: reading the recording and the joint fit (intrinsics with k3, hand-eye, board pose,
  joint offsets) as `robocal run`'s identify solves it (`pipeline.identify.least_squares.fit`).

    .venv/bin/python benchmarks/bench_camera_speed.py [--images 100] [--workers 2] [--ros2]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

TARGET = "chessboard:9x6:0.03"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", type=int, default=100)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--ros2", action="store_true", help="time `robocal import ros2 --target` on a bag of the images")
    a = ap.parse_args()

    from r6_robot import BARE_URDF
    from typer.testing import CliRunner

    from pipeline.camera.targets import parse as parse_target
    from pipeline.cli import app, load_commands
    from pipeline.identify.complexity import fixed_for
    from pipeline.identify.least_squares import FitOptions, fit
    from pipeline.measurements.camera import CameraModel
    from pipeline.models.urdf import parse
    from pipeline.models.urdf_arm import UrdfArm
    from pipeline.recording.reader import read_recording
    from pipeline.simulate import camera_images as ci
    from pipeline.systems import urdf_robot

    model = CameraModel(UrdfArm(parse(BARE_URDF, "b", "l6")), mount="tip", image_size=(640, 480))
    tgt = parse_target(TARGET)
    rng = np.random.default_rng(0)
    k = np.array([520.0, 522.0, 318.0, 242.0, -0.25, 0.09, 0.001, -0.0005, -0.01])
    qh = np.array([0.0, 0.6, -1.2, 0.0, 0.8, 0.0])
    x = ci.truth(model, qh, k, tgt, rng)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        ci.write_campaign(tmp / "img", model, x, ci.poses(model, x, qh, a.images, tgt, rng), tgt, rng)
        (tmp / "r6.urdf").write_text(BARE_URDF)
        print(f"rendered {a.images} images in {time.perf_counter() - t0:.1f} s (not timed below)")
        load_commands(["import"])
        if a.ros2:
            import cv2

            from pipeline.simulate.ros2_camera_bag import CameraBagLayout, write_images_bag

            files = sorted((tmp / "img").glob("img_*.png"))
            q = np.loadtxt(tmp / "img" / "joints.csv", delimiter=",", skiprows=1, usecols=range(1, 7))
            write_images_bag(tmp / "bag", model.kin.joint_names, q,
                             lambda i, _: cv2.imread(str(files[i]), cv2.IMREAD_GRAYSCALE), model.image_size,
                             np.r_[k[:4] + [5.0, -4.0, 3.0, -2.0], np.zeros(5)], CameraBagLayout())  # a rough K
            print(f"wrote the bag ({sum(f.stat().st_size for f in (tmp / 'bag').iterdir()) / 1e6:.1f} MB, not timed)")
        t1 = time.perf_counter()
        if a.ros2:
            res = CliRunner().invoke(app, ["import", "ros2", str(tmp / "bag"), "--target", TARGET, "--urdf",
                                           str(tmp / "r6.urdf"), "--root", "b", "--tip", "l6", "--distortion-terms",
                                           "5", "--workers", str(a.workers), "--out", str(tmp / "rec.mcap")])
        else:
            res = CliRunner().invoke(app, ["import", "images", str(tmp / "img"), "--target", TARGET, "--joints",
                                           str(tmp / "img" / "joints.csv"), "--urdf", str(tmp / "r6.urdf"), "--root",
                                           "b", "--tip", "l6", "--distortion-terms", "5", "--workers", str(a.workers),
                                           "--out", str(tmp / "rec.mcap")])
        if res.exit_code != 0:
            raise SystemExit(res.output)
        t2 = time.perf_counter()
        m, data = urdf_robot.load(read_recording(tmp / "rec.mcap"))
        f = fit(m, data, FitOptions(fixed=fixed_for(m, ["registration", "lens k3", "joint offsets"]) +
                                    ("j1.offset", "j6.offset"), before=False))
        t3 = time.perf_counter()
    n_img = len(np.unique(data["image"]))
    print(f"detection + recording{' (from the ROS 2 bag)' if a.ros2 else ''}: {t2 - t1:.1f} s ({a.workers} workers, {n_img} of {a.images} images used, "
          f"{len(data['corner'])} corners)")
    print(f"calibration (read + joint fit, {int(f.free.sum())} parameters): {t3 - t2:.1f} s, "
          f"RMS {np.sqrt(np.mean(f.residuals_after ** 2)):.3f} px")
    print(f"total detection + calibration: {t3 - t1:.1f} s (goal: under 30 s on 2 cores)")


if __name__ == "__main__":
    main()
