"""The camera run's views: the report's camera section (per-image reprojection RMS, residual quiver,
coverage, outlier corners; px) and run.rrd's camera entities (frusta at the calibrated camera
poses, the board's corners, each kept image with detected / reprojected corners and residual
lines) — read back with rerun's own reader and checked against the run's artefacts, OpenCV's
projection and the simulated truth.

The run: 10 images rendered by OpenCV from a 6R arm with a spherical wrist (reachable views of a
9×6 board drawn by `pipeline.plan.camera`), imported with --keep-images, `robocal run`."""

from __future__ import annotations

import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import run_cli
from r6_robot import WRIST_URDF
from test_rerun_rrd import _read

from pipeline.camera.targets import parse as parse_target
from pipeline.measurements.camera import CameraModel
from pipeline.models.urdf import parse
from pipeline.models.urdf_arm import UrdfArm, frame_matrix
from pipeline.plan import camera as pc
from pipeline.plan import camera_check as cc
from pipeline.report.camera import CameraFigures, camera_figures
from pipeline.simulate import camera_images as ci

# extended (`make test-extended`, outside CI's 20-minute budget): the camera's viewer screenshots; CI keeps test_rerun_robot (the viewer) and test_camera_import
pytestmark = pytest.mark.extended

TARGET = "chessboard:9x6:0.03"


@pytest.fixture(scope="module")
def cam_run(tmp_path_factory) -> SimpleNamespace:
    tmp = tmp_path_factory.mktemp("camrun")
    model = CameraModel(UrdfArm(parse(WRIST_URDF, "base", "tool")), mount="tip", n_dist=5, image_size=(640, 480))
    tgt = parse_target(TARGET)
    setup = pc.Setup(tgt, np.array([520.0, 520, 319.5, 239.5, 0, 0, 0, 0, 0]),
                     np.array([0.0, 0.3, -0.5, 0.0, 0.8, 0.0]), 0.5)
    x = pc.nominal(model, setup)
    cand = pc.candidate_views(model, x, setup, 10, np.random.default_rng(0))
    truth = cc.true_cell(model, x, np.random.default_rng(1), ("j1.offset", "j6.offset"))
    ci.write_campaign(tmp / "images", model, truth, cand.q, tgt, np.random.default_rng(2))
    (tmp / "six.urdf").write_text(WRIST_URDF)
    r = run_cli("import", "images", tmp / "images", "--target", TARGET, "--joints", tmp / "images" / "joints.csv",
                "--urdf", tmp / "six.urdf", "--root", "base", "--tip", "tool", "--distortion-terms", "5",
                "--workers", "1", "--keep-images", "--out", tmp / "rec.mcap")
    assert r.returncode == 0, r.stderr
    r = run_cli("run", tmp / "rec.mcap", "--out", tmp / "run")
    assert r.returncode == 0, r.stderr[-3000:]
    return SimpleNamespace(dir=tmp / "run", images=tmp / "images", model=model, truth=truth, target=tgt)


def _artefacts(run: Path):
    from pipeline.report.artefacts import load_run

    return load_run(run)


def test_report_lists_each_image_with_its_reprojection_rms(cam_run):
    html = (cam_run.dir / "report.html").read_text(encoding="utf-8")
    assert '<section id="camera">' in html and '<a href="#camera">Camera images</a>' in html
    res = pq.read_table(cam_run.dir / "identify" / "residuals.parquet").to_pydict()
    meas = pq.read_table(cam_run.dir / "ingest" / "measurements.parquet").to_pydict()
    label = dict(zip(meas["record"], meas["label"]))
    r = np.c_[res["after_0"], res["after_1"]]
    used = np.asarray(res["used"], bool)
    labels = np.array([label[k] for k in res["record"]])
    section = html[html.index('<section id="camera">'):]
    section = section[:section.index("</section>")]
    for name in sorted(set(labels)):  # the table row: image, corners, used, RMS after (px) recomputed here
        m = (labels == name) & used
        rms = np.sqrt(np.mean(r[m] ** 2))
        row = re.search(rf"<tr><td>{re.escape(name)}</td>(.*?)</tr>", section)
        assert row, name
        cells = re.findall(r'<td class="n">([^<]*)</td>', row.group(1))
        assert cells[0] == str((labels == name).sum()) and cells[1] == str(m.sum())
        assert cells[2] == f"{rms:.4f}", (name, cells, rms)
    assert len(re.findall(r"<tr><td>img_\d{3}\.png</td>", section[:section.index("</table>")])) == 10
    for label_px in ("reprojection RMS (px)", "u (px)", "v (px)", "corners per cell"):
        assert label_px in section, label_px
    for fig in ("fig-camera-images", "fig-camera-quiver", "fig-camera-coverage"):
        assert f'id="{fig}"' in section
    n_rej = int((~used).sum())
    if n_rej:  # every corner the fit rejected is listed among the outliers
        assert "Outlier corners (" in section and section.count("rejected by the fit") == n_rej


def test_outlier_corners_are_the_rejected_and_the_gross_ones():
    rng = np.random.default_rng(0)
    n = 200
    after = rng.normal(0, 0.05, (n, 2))
    after[17] = [0.9, -0.2]  # 18 robust σ: a gross error the fit kept
    used = np.ones(n, bool)
    used[42] = False  # rejected by the fit
    f = CameraFigures(np.repeat(np.arange(4), 50), np.repeat([f"i{k}" for k in range(4)], 50), np.tile(np.arange(50), 4),
                      rng.uniform(0, [640, 480], (n, 2)), after, after, used, (640, 480))
    out = f.outliers()
    assert [(o["label"], o["corner"]) for o in out][:1] == [("i0", 17)]
    assert {(o["label"], o["corner"]) for o in out} == {("i0", 17), ("i0", 42)}
    assert [o["why"] for o in out if o["corner"] == 42] == ["rejected by the fit"]
    cov = f.coverage()
    assert cov.shape == (6, 8) and cov.sum() == n


def test_a_run_that_is_not_a_camera_has_no_camera_section():
    art = SimpleNamespace(metadata={"robocal.campaign": {"measure": "point"}}, measurements={"record": np.arange(3)},
                          residuals={}, used=np.ones(3, bool))
    assert camera_figures(art) is None


def _project(K: np.ndarray, dist: np.ndarray, T_cam_world: np.ndarray, P: np.ndarray) -> np.ndarray:
    import cv2

    rv = cv2.Rodrigues(T_cam_world[:3, :3])[0]
    return cv2.projectPoints(P, rv, T_cam_world[:3, 3], K, dist)[0].reshape(-1, 2)


def _transform(static: dict) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = np.array(static["Transform3D:mat3x3"][0], float).reshape(3, 3).T  # rerun stores column-major
    T[:3, 3] = static["Transform3D:translation"][0]
    return T


def test_rrd_camera_frusta_board_and_images(cam_run):
    rrd = _read(cam_run.dir / "run.rrd")
    cams = sorted(e for e in rrd if e.startswith("world/base/cameras/") and e.count("/") == 3)
    assert len(cams) == 10
    art = _artefacts(cam_run.dir)
    fit = art.fit
    x = np.asarray(fit["x"], float)
    names = fit["names"]
    ib = names.index("base.x")
    B = _transform(rrd["world/base"]["static"])
    assert np.allclose(B, frame_matrix(x[ib:ib + 6]), atol=1e-6)  # world (board) ← robot base: the calibrated base.*
    corners = np.array(rrd["world/base/board/corners"]["static"]["Points3D:positions"], float)
    assert corners.shape == (cam_run.target.n_corners, 3)
    world = corners @ B[:3, :3].T + B[:3, 3]  # in the board frame: the target's own corners
    assert np.allclose(world, cam_run.target.points, atol=1e-5)
    meas = art.measurements  # ingest's table, k-vector columns restored
    px = np.asarray(meas["pixel"], float).reshape(-1, 2)
    lab = np.asarray(meas["label"])
    k = x[cam_run.model.n_kin:]
    for e in cams:
        name = e.rsplit("/", 1)[1]
        st = rrd[e]["static"]
        K = np.array(st["Pinhole:image_from_camera"][0], float).reshape(3, 3).T
        assert np.allclose(K, [[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1]], atol=1e-3)
        assert st["Pinhole:resolution"][0] == [640.0, 480.0]
        T_base_cam = _transform(st)
        det = np.array(rrd[f"{e}/detected"]["static"]["Points2D:positions"], float)
        assert np.allclose(det, px[lab == name], atol=1e-4)  # the image's detections as imported
        rep = np.array(rrd[f"{e}/reprojected"]["static"]["Points2D:positions"], float)
        ids = np.array(rrd[f"{e}/detected"]["static"]["Points2D:labels"], int)
        # the logged camera pose, intrinsics and board put through OpenCV's projection land on the reprojected corners
        ocv = _project(K, k[4:], np.linalg.inv(T_base_cam), corners[ids])
        assert np.abs(ocv - rep).max() < 2e-3, np.abs(ocv - rep).max()
        assert np.sqrt(np.mean((rep - det) ** 2)) < 0.1  # px: the calibration fits the images
        lines = [e2 for e2 in rrd if e2.startswith(f"{e}/residuals_x")]
        assert len(lines) == 1
        s = int(lines[0].rsplit("_x", 1)[1])
        strips = np.array(rrd[lines[0]]["static"]["LineStrips2D:strips"], float)
        assert np.allclose(strips[:, 0], det, atol=1e-4) and np.allclose(strips[:, 1], det + s * (rep - det), atol=1e-2)
        blob = rrd[f"{e}/image"]["static"]["EncodedImage:blob"]
        blob = blob[0] if blob and isinstance(blob[0], list) else blob  # one blob per instance
        assert bytes(blob) == (cam_run.images / name).read_bytes()  # the kept image, byte for byte
    # the calibrated camera poses against the simulated truth's (robot base frame)
    from pipeline.visualize.camera import camera_poses

    q = np.array([np.asarray(meas["joint_positions"]).reshape(len(lab), -1)[np.flatnonzero(lab == c.rsplit("/", 1)[1])[0]]
                  for c in cams], float)
    T_true, _ = camera_poses(cam_run.model, cam_run.truth, q)
    T_log = np.array([_transform(rrd[c]["static"]) for c in cams])
    assert np.abs(T_log[:, :3, 3] - T_true[:, :3, 3]).max() < 2e-3  # m


def test_rerun_viewer_shows_the_image_with_its_board(cam_run, tmp_path):
    """The real viewer (headless, Mesa): the camera run's 2-D image view shows the rendered board
    (dark and light squares) and the 3-D view holds the robot."""
    from viewer_support import viewer_screenshot

    img = viewer_screenshot(cam_run.dir / "run.rrd", tmp_path / "viewer.png")
    h, w = img.shape[:2]
    panel = img[int(0.55 * h):int(0.74 * h), int(0.59 * w):int(0.76 * w)].mean(axis=2)
    assert (panel < 0.2).mean() > 0.02 and (panel > 0.8).mean() > 0.02, "no board image in the image view"
    R, G, B = img[..., 0], img[..., 1], img[..., 2]
    scene = (slice(int(0.05 * h), int(0.75 * h)), slice(int(0.13 * w), int(0.53 * w)))
    assert ((B > 0.45) & (B > R + 0.2) & (B > G + 0.1))[scene].mean() > 5e-3, "no robot in the 3-D view"


def test_chromium_renders_the_camera_section(cam_run, tmp_path):
    """Headless Chromium: the camera section, its px labels and its three plots in the rendered DOM."""
    from test_report_html import _chromium

    dom = _chromium(["--dump-dom", (cam_run.dir / "report.html").resolve().as_uri()], tmp_path)
    assert dom.returncode == 0, dom.stderr[-2000:]
    sec = dom.stdout[dom.stdout.index('<section id="camera">'):]
    sec = sec[:sec.index("</section>")]
    assert "Camera images" in sec and "RMS after (px)" in sec and sec.count("<svg") == 3


def test_eye_to_hand_rrd_draws_the_fixed_camera_and_the_moving_board(tmp_path):
    """Eye-to-hand (board on the flange): one camera pose for every image, the board's corners
    per image where the robot carried them; OpenCV's projection of them through the logged
    camera lands on the logged reprojected corners."""
    import rerun as rr

    from pipeline.visualize.camera import log_camera

    model = CameraModel(UrdfArm(parse(WRIST_URDF, "base", "tool")), mount="world", n_dist=5, image_size=(640, 480))
    tgt = parse_target(TARGET)
    setup = pc.Setup(tgt, np.array([520.0, 520, 319.5, 239.5, -0.2, 0.05, 0, 0, 0]),
                     np.array([0.0, 0.3, -0.5, 0.0, 0.8, 0.0]), 0.5)
    x = pc.nominal(model, setup)
    cand = pc.candidate_views(model, x, setup, 4, np.random.default_rng(3))
    table = pc.image_table(model, x, cand.q, tgt)
    table["pixel"] = table["pixel"] + np.random.default_rng(4).normal(0, 0.05, table["pixel"].shape)
    table["label"] = np.repeat([f"v{i}" for i in range(4)], tgt.n_corners)
    rec = rr.RecordingStream("robocal-test", recording_id="eye-to-hand")
    rec.save(tmp_path / "e2h.rrd")
    paths = log_camera(rec, model, table, x, None, tgt.points)
    rec.flush()
    rec.disconnect()
    rrd = _read(tmp_path / "e2h.rrd")
    assert set(paths) <= set(rrd) and "world/base/board/corners" not in rrd
    B = _transform(rrd["world/base"]["static"])
    cams = [_transform(rrd[f"world/base/cameras/v{i}"]["static"]) for i in range(4)]
    assert all(np.allclose(c, cams[0], atol=1e-6) for c in cams)  # the camera does not move
    assert np.allclose(B @ cams[0], np.eye(4), atol=1e-5)  # eye-to-hand: the world is the camera frame
    k = x[model.n_kin:]
    for i in range(4):
        P = np.array(rrd[f"world/base/boards/v{i}"]["static"]["Points3D:positions"], float)
        rep = np.array(rrd[f"world/base/cameras/v{i}/reprojected"]["static"]["Points2D:positions"], float)
        ocv = _project(pc_camera_matrix(k), k[4:], np.linalg.inv(cams[i]), P)
        assert np.abs(ocv - rep).max() < 2e-3
        det = np.array(rrd[f"world/base/cameras/v{i}/detected"]["static"]["Points2D:positions"], float)
        assert np.allclose(det, table["pixel"][table["image"] == i], atol=1e-4)
    assert not any(p.endswith("/image") for p in rrd)  # no image kept: none drawn


def pc_camera_matrix(k: np.ndarray) -> np.ndarray:
    return np.array([[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1.0]])


def test_dense_residual_field_is_drawn_as_cell_means():
    """More corners than arrows a reader can tell apart: the quiver draws each ≈ 40 px cell's mean
    residual — a radial field keeps its direction and size there."""
    from pipeline.report.camera import MAX_ARROWS, field

    rng = np.random.default_rng(1)
    n = MAX_ARROWS + 1000
    px = rng.uniform(0, [640, 480], (n, 2))
    after = 2e-3 * (px - [320, 240])  # a radial residual field, px
    f = CameraFigures(np.zeros(n, int), np.full(n, "a"), np.arange(n), px, after, after, np.ones(n, bool), (640, 480))
    at, vec, what = field(f)
    assert len(at) <= 16 * 12 and "cell" in what
    assert np.allclose(vec, 2e-3 * (at - [320, 240]), atol=1e-12)  # the mean of a linear field at the cell's mean position
    few = CameraFigures(np.zeros(50, int), np.full(50, "a"), np.arange(50), px[:50], after[:50], after[:50],
                        np.ones(50, bool), (640, 480))
    assert np.array_equal(field(few)[1], after[:50])  # every corner drawn


def test_the_diagnosis_of_a_camera_run_speaks_px(cam_run):
    """A camera's residuals are px: the diagnosis says so in its document, and neither its report section nor
    `robocal diagnose`'s text turns them into mm."""
    import json

    from pipeline.report.html import diagnosis_section

    doc = json.loads((cam_run.dir / "diagnose" / "diagnosis.json").read_text())
    assert doc["residual_unit"] == "px"
    section = diagnosis_section(_artefacts(cam_run.dir))
    assert "held-out rms" in section.lower() and re.search(r"\d px\b", section)
    assert not re.search(r"\d mm\b", section), re.findall(r".{40}\d mm\b", section)
    r = run_cli("diagnose", cam_run.dir.parent / "rec.mcap", "--out", cam_run.dir.parent / "diag")
    assert r.returncode == 0, r.stderr[-2000:]
    assert re.search(r"held-out RMS [\d.]+ px → [\d.]+ px", r.stdout) and not re.search(r"\d mm\b", r.stdout), r.stdout
