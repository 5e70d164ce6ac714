"""Real eye-in-hand images (KUKA, 24×17 chessboard; /work/shared/real-data/handeye_rwhe_kuka2): robocal's
joint fit predicts images it never saw better than OpenCV's calibrateCamera + every calibrateHandEye
method and calibrateRobotWorldHandEye, on the same detections and held-out images — reprojection (px)
and the board's position in the robot base frame (mm)."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import bench_handeye as bh  # noqa: E402


@pytest.fixture(scope="module")
def kuka(tmp_path_factory):
    if not bh.DATA.is_dir():
        pytest.skip(f"{bh.DATA} is absent: the real KUKA hand-eye images (see docs/guide/camera.md) are not on this machine")
    return bh.load(bh.DATA, tmp_path_factory.mktemp("kuka"))


def test_all_sixteen_images_detected(kuka):
    model, data = kuka
    assert len(set(data["image"].tolist())) == 16 and len(data["corner"]) == 16 * 24 * 17


def test_held_out_beats_every_opencv_method(kuka):
    model, data = kuka
    out = bh.compare(model, data, folds=4, repeats=1, sigma=False, progress=lambda *_: None)
    m = out["methods"]
    ours = m.pop("robocal")
    for name, v in m.items():
        assert ours["reprojection_rms_px"] < v["reprojection_rms_px"], (name, ours, v)
        assert ours["board_rms_mm"] < v["board_rms_mm"], (name, ours, v)
