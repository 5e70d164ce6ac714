"""The camera views on real images (KUKA eye-in-hand, 16 images 1920×1200, 24×17 chessboard;
../shared/real-data/handeye_rwhe_kuka2, see its SOURCE.md): the report's per-image figures and
run.rrd's frusta, board and images from robocal's joint fit of the real detections, checked with
OpenCV's projection and against the image files."""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import run_cli
from test_camera_views import _project, _transform
from test_rerun_rrd import _read

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import bench_handeye as bh  # noqa: E402


@pytest.fixture(scope="module")
def kuka(tmp_path_factory):
    if not bh.DATA.is_dir():
        pytest.skip(f"{bh.DATA} is absent: the real KUKA hand-eye images (see docs/guide/camera.md) are not on this machine")
    from pipeline.identify.complexity import fixed_for
    from pipeline.identify.least_squares import FitOptions, fit
    from pipeline.recording.reader import read_recording
    from pipeline.systems import urdf_robot

    tmp = tmp_path_factory.mktemp("kuka")
    rec = tmp / "kuka.mcap"
    r = run_cli("import", "images", bh.DATA, "--target", bh.TARGET, "--poses", bh.DATA / "RobotPosesVec.txt",
                "--keep-images", "--out", rec)
    assert r.returncode == 0, r.stderr
    model, data = urdf_robot.load(read_recording(rec))
    f = fit(model, data, FitOptions(fixed=fixed_for(model, ["registration"]), before=False))
    return SimpleNamespace(rec=rec, model=model, data=data, fit=f)


def test_report_figures_of_the_real_images(kuka):
    from pipeline.report.camera import camera_figures, section

    d, r = kuka.data, kuka.fit.residuals_after
    art = SimpleNamespace(metadata={"robocal.campaign": {"measure": "camera", "image_size": [1920, 1200]}},
                          measurements=d, residuals={"record": d["record"], "after_0": r[:, 0], "after_1": r[:, 1]},
                          used=np.ones(len(r), bool))
    f = camera_figures(art)
    rows = f.per_image()
    assert len(rows) == 16 and all(x["corners"] == 24 * 17 for x in rows)
    for x in rows:  # per-image RMS (px) recomputed from the fit's residuals
        m = np.asarray(d["label"]) == x["label"]
        assert np.isclose(x["rms_after_px"], np.sqrt(np.mean(r[m] ** 2)))
    assert 0.4 < np.sqrt(np.mean(r ** 2)) < 1.0  # px: the documented 0.70 px of the real images
    cov = f.coverage()
    assert cov.sum() == 16 * 24 * 17
    # what the coverage figure shows of this campaign: the board kept to the middle of the sensor, its
    # corners never seen there (distortion at the image's corners is extrapolated)
    assert cov[0, 0] == cov[0, -1] == cov[-1, 0] == cov[-1, -1] == 0 and cov[2:4, 3:5].min() > 100
    html = section(art)
    assert html.count("<svg") == 3 and "im_01.bmp" in html


def test_rrd_of_the_real_images(kuka, tmp_path):
    import cv2
    import rerun as rr

    from pipeline.visualize.camera import log_camera

    rec = rr.RecordingStream("robocal-test", recording_id="kuka")
    rec.save(tmp_path / "kuka.rrd")
    log_camera(rec, kuka.model, kuka.data, kuka.fit.x, kuka.rec, bh_points())
    rec.flush()
    rec.disconnect()
    rrd = _read(tmp_path / "kuka.rrd")
    cams = sorted(e for e in rrd if e.startswith("world/base/cameras/") and e.count("/") == 3)
    assert len(cams) == 16
    corners = np.array(rrd["world/base/board/corners"]["static"]["Points3D:positions"], float)
    k = kuka.fit.x[kuka.model.n_kin:]
    lab = np.asarray(kuka.data["label"])
    px = np.asarray(kuka.data["pixel"], float)
    for e in cams:
        name = e.rsplit("/", 1)[1]
        st = rrd[e]["static"]
        K = np.array(st["Pinhole:image_from_camera"][0], float).reshape(3, 3).T
        assert st["Pinhole:resolution"][0] == [1920.0, 1200.0]
        rep = np.array(rrd[f"{e}/reprojected"]["static"]["Points2D:positions"], float)
        det = np.array(rrd[f"{e}/detected"]["static"]["Points2D:positions"], float)
        ids = np.array(rrd[f"{e}/detected"]["static"]["Points2D:labels"], int)
        assert np.allclose(det, px[lab == name], atol=1e-3)
        ocv = _project(K, k[4:], np.linalg.inv(_transform(st)), corners[ids])
        assert np.abs(ocv - rep).max() < 5e-3
        assert np.sqrt(np.mean((rep - det) ** 2)) < 1.5  # px: each real image fitted
        blob = rrd[f"{e}/image"]["static"]["EncodedImage:blob"]
        blob = blob[0] if blob and isinstance(blob[0], list) else blob
        assert rrd[f"{e}/image"]["static"]["EncodedImage:media_type"] == ["image/png"]  # a BMP re-encoded for the viewer
        shown = cv2.imdecode(np.frombuffer(bytes(blob), np.uint8), cv2.IMREAD_UNCHANGED)
        assert np.array_equal(shown, cv2.imread(str(bh.DATA / name), cv2.IMREAD_UNCHANGED))  # lossless


def bh_points() -> np.ndarray:
    from pipeline.camera.targets import parse

    return parse(bh.TARGET).points
