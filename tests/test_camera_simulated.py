"""Simulated camera campaigns with known truth: images rendered by OpenCV (remap of a board texture
through the lens's exact inverse, blur, noise) from a 6R URDF robot with joint offset errors (j2, j3);
`robocal import images` detects them; the joint fit recovers intrinsics, hand-eye, board pose and
joint offsets within their stated σ."""

import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

sys.path.insert(0, str(Path(__file__).parent))
from r6_robot import BARE_URDF  # noqa: E402

from pipeline.camera.targets import parse as parse_target  # noqa: E402
from pipeline.camera.uncertainty import clustered_fit  # noqa: E402
from pipeline.cli import app, load_commands  # noqa: E402
from pipeline.identify.complexity import fixed_for  # noqa: E402
from pipeline.identify.least_squares import FitOptions  # noqa: E402
from pipeline.measurements.camera import CameraModel  # noqa: E402
from pipeline.models.urdf import parse  # noqa: E402
from pipeline.models.urdf_arm import UrdfArm  # noqa: E402
from pipeline.recording.reader import read_recording  # noqa: E402
from pipeline.simulate import camera_images as ci  # noqa: E402
from pipeline.systems import urdf_robot  # noqa: E402

TARGET = "chessboard:9x6:0.03"
K_TRUE = np.array([520.0, 522.0, 318.0, 242.0, -0.25, 0.09, 0.001, -0.0005, -0.01])
Q_HOME = np.array([0.0, 0.6, -1.2, 0.0, 0.8, 0.0])


def _campaign(tmp: Path, mount: str, n: int, noise: float, seed: int = 3):
    desc = parse(BARE_URDF, "b", "l6")
    model = CameraModel(UrdfArm(desc), mount=mount, n_dist=5, image_size=(640, 480))
    tgt = parse_target(TARGET)
    rng = np.random.default_rng(seed)
    x = ci.truth(model, Q_HOME, K_TRUE, tgt, rng)
    names = model.parameter_names()
    for i, nm in enumerate(names):  # truth: offset errors of j2 and j3 only (j1 and j6 turn as the board and
        # the hand-eye do; j4's and j5's offsets are nearly one another's negative in these views)
        if nm.startswith(("j1.", "j4.", "j5.", "j6.")) or nm.endswith((".rx", ".ry", ".rz")):
            x[i] = model.nominal()[i]
        elif nm.endswith((".x", ".y", ".z")) and not nm.startswith(("base.", "tool.")):
            x[i] = model.nominal()[i]
    q = ci.poses(model, x, Q_HOME, n, tgt, rng)
    ci.write_campaign(tmp / "images", model, x, q, tgt, rng, noise=noise, blur_px=0.6 if noise else 0.0)
    (tmp / "r6.urdf").write_text(BARE_URDF)
    load_commands(["import"])
    res = CliRunner().invoke(app, ["import", "images", str(tmp / "images"), "--target", TARGET, "--joints",
                                   str(tmp / "images" / "joints.csv"), "--urdf", str(tmp / "r6.urdf"), "--root", "b",
                                   "--tip", "l6", "--camera-on", mount, "--distortion-terms", "5", "--workers", "1",
                                   "--out", str(tmp / "rec.mcap")])
    assert res.exit_code == 0, res.output
    m, data = urdf_robot.load(read_recording(tmp / "rec.mcap"))
    assert m.parameter_names() == names and m.mount == mount
    return m, data, x


def _fit(model, data):
    # j1's and j6's offsets turn the chain exactly as the board's and the hand-eye's rotations do: held
    fixed = fixed_for(model, ["registration", "lens k3", "joint offsets"]) + ("j1.offset", "j6.offset")
    return clustered_fit(model, data, FitOptions(fixed=fixed, before=False))[0]


@pytest.mark.parametrize("mount", ["tip", "world"])
def test_recovers_truth_within_stated_sigma(tmp_path, mount):
    model, data, truth = _campaign(tmp_path, mount, n=14, noise=2.0)
    f = _fit(model, data)
    names = np.array(f.names)
    free = f.free
    z = (f.x - truth)[free] / f.std[free]
    worst = int(np.argmax(np.abs(z)))
    assert np.all(np.abs(z) < 4), f"{names[free][worst]}: {z[worst]:+.1f} σ off the truth"
    for p in ("camera.fx", "camera.k1", "tool.x", "tool.roll", "j2.offset", "j3.offset"):
        assert p in names[free], f"{p} was not identified"
    assert np.sqrt(np.mean(f.residuals_after**2)) < 0.1  # px: the detector's noise floor, not a model error


def test_noise_free_images_recover_to_detector_precision(tmp_path):
    model, data, truth = _campaign(tmp_path, "tip", n=10, noise=0.0, seed=5)
    f = _fit(model, data)
    rms = float(np.sqrt(np.mean(f.residuals_after**2)))
    assert rms < 0.05, rms  # px: the detector's own precision on clean renders (≈ 0.02 px)
    names = f.names
    fx = names.index("camera.fx")
    assert abs(f.x[fx] - truth[fx]) < 0.2  # px of focal length
    it = names.index("tool.x")
    assert np.linalg.norm(f.x[it:it + 3] - truth[it:it + 3]) < 2e-4  # m: hand-eye translation
