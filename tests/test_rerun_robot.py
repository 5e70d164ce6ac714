"""The robot in run.rrd, logged through rerun's URDF support and read back with rerun's own reader
(rerun.chunk.RrdReader): the URDF's links by name, and their frames (placement, the loader's static
transforms, the joint transforms per time step) checked against yourdfpy's forward kinematics of the
calibrated model.urdf, the measured points and the residuals the identify stage wrote; and the real
rerun viewer's screenshot under Xvfb.

Uses the real TIAGo motion-capture campaign (/work/shared/real-data/figaroh_tiago_mocap; skips
where it is absent)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy.spatial.transform import Rotation

from conftest import run_cli
from test_rerun_rrd import _read

REPO = Path(__file__).resolve().parents[1]
REAL = REPO.parent.parent / "shared" / "real-data"
if not REAL.is_dir():
    REAL = Path("/work/shared/real-data")
TIAGO = REAL / "figaroh_tiago_mocap"
needs_tiago = pytest.mark.skipif(not TIAGO.is_dir(), reason=f"real data not here: {TIAGO}")


@pytest.fixture(scope="module")
def tiago_run(tmp_path_factory) -> Path:
    if not TIAGO.is_dir():
        pytest.skip(f"real data not here: {TIAGO}")
    d = tmp_path_factory.mktemp("tiago")
    rec = d / "tiago.mcap"
    p = run_cli("import", "csv", TIAGO / "qualysis_base_hand_calibration.csv", "--urdf", TIAGO / "tiago_48_schunk.urdf",
                "--root", "base_footprint", "--tip", "wrist_ft_tool_link", "--measure", "point",
                "--position-cols", "x1,y1,z1", "--out", rec)
    assert p.returncode == 0, p.stderr
    p = run_cli("run", rec, "--out", d / "run")
    assert p.returncode == 0, p.stderr
    assert (d / "run" / "run.rrd").is_file(), p.stderr
    return d / "run"


@pytest.fixture(scope="module")
def rrd(tiago_run) -> dict:
    return _read(tiago_run / "run.rrd")


def _capsule_ends(e: dict, n_links: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times (N,), capsule starts and ends (N, n_links, 3) of a Capsules3D entity logged per time (seed
    000's D-H arm, drawn as capsules)."""
    t = np.asarray(e["index"]["time"], np.int64)
    tr = np.array(e["rows"]["Capsules3D:translations"], float).reshape(len(t), n_links, 3)
    qt = np.array(e["rows"]["Capsules3D:quaternions"], float).reshape(len(t), n_links, 4)
    L = np.array(e["rows"]["Capsules3D:lengths"], float).reshape(len(t), n_links)
    z = Rotation.from_quat(qt.reshape(-1, 4)).apply([0, 0, 1]).reshape(len(t), n_links, 3)
    return t, tr, tr + z * L[..., None]


@needs_tiago
def test_robot_entities_and_no_whitespace(rrd):
    """Both robots' links by their URDF names (rerun's URDF loader), their joints' transforms on `time`."""
    links = {"torso_lift_link", "arm_1_link", "arm_4_link", "arm_7_link", "wrist_ft_tool_link"}
    for w in ("nominal", "calibrated"):
        drawn = {e.split("/")[3] for e in rrd if e.startswith(f"world/robot_{w}/visual_geometries/")}
        assert links <= drawn, sorted(links - drawn)
        assert {f"world/robot_{w}/joints/{j}" for j in ("torso_lift_joint", "arm_1_joint", "arm_7_joint")} <= set(rrd)
        assert f"world/robot_{w}/placement" in rrd
    want = {"world/instrument", "world/measured", "encoder/postures", "world/tips/nominal", "world/tips/calibrated"}
    assert want <= set(rrd), sorted(want - set(rrd))
    assert not [e for e in rrd if any(c.isspace() for c in e)], "entity paths with whitespace"
    names = rrd["encoder/postures"]["static"]["SeriesLines:names"]
    assert names[0] == "torso_lift_joint (m)" and names[1] == "arm_1_joint (rad)"  # the URDF's own names and units
    assert "tiago" in rrd["summary"]["static"]["TextDocument:text"][0].splitlines()[0]


@needs_tiago
def test_calibrated_robot_is_the_calibrated_urdf(tiago_run):
    """Every link frame of the calibrated robot, composed from run.rrd's transforms (placement in the world,
    the URDF loader's static transforms, the joint transforms at each time), is where yourdfpy places that
    link of model.urdf in the instrument frame, at every measurement posture of the campaign."""
    from pipeline.models.urdf import load_urdf_model
    from pipeline.recording.reader import read_recording
    from pipeline.systems.registry import detect
    from rrd_frames import pose, read_frames

    rec = read_recording(tiago_run.parent / "tiago.mcap")
    model, table = detect(rec).load(rec)
    u = load_urdf_model((tiago_run / "identify" / "model.urdf").read_text())
    static, timed = read_frames(tiago_run / "run.rrd")
    t = timed["calibrated/arm_1_link"][1]
    order = np.argsort(table["timestamp_ns"])
    assert np.array_equal(t, np.asarray(table["timestamp_ns"])[order])
    joints = model.kin.joint_names
    checked = 0
    for i in range(0, len(t), max(1, len(t) // 6)):
        k = int(np.flatnonzero(table["timestamp_ns"] == t[i])[0])
        u.update_cfg(dict(zip(joints, table["joint_positions"][k])))
        for link in ("torso_lift_link", "arm_1_link", "arm_4_link", "arm_7_link", "wrist_ft_tool_link", "robocal_tool"):
            got = pose(static, timed, f"calibrated/{link}", "tf#/world", i)
            np.testing.assert_allclose(got[:3, 3], u.get_transform(link, "robocal_instrument")[:3, 3], atol=2e-5,
                                       err_msg=f"{link} at posture {k}")
            checked += 1
    assert checked > 30


@needs_tiago
def test_nominal_is_registered_like_before_calibration(rrd, tiago_run):
    """Nominal tool points minus measured points are the "before" residuals (same registration),
    not a 2 m instrument offset; the correction lines are mm, not metres."""
    res = pq.read_table(tiago_run / "identify" / "residuals.parquet").to_pydict()
    p0 = np.array(rrd["world/tips/nominal"]["static"]["Points3D:positions"])
    m = np.array(rrd["world/measured"]["static"]["Points3D:positions"])
    before = np.column_stack([res[f"before_{j}"] for j in range(3)])
    np.testing.assert_allclose(p0 - m, before, atol=2e-6)
    corr = np.array(rrd["world/tips/correction"]["static"]["LineStrips3D:strips"])
    assert np.max(np.linalg.norm(corr[:, 1] - corr[:, 0], axis=1)) < 0.02
    arrows = [e for e in rrd if e.startswith("world/residuals/after_x")]
    assert arrows == ["world/residuals/after_x10"]  # mm residuals magnified to cm, not ×100 to decimetres


@needs_tiago
def test_rerun_viewer_shows_the_robot(tiago_run, tmp_path):
    """The real viewer, headless (Xvfb + Mesa lavapipe): the 3-D view holds the calibrated robot
    (translucent blue capsules) and the nominal one (red) inside it.  Its own port: a viewer
    already listening on rerun's default port would otherwise be handed the recording."""
    from viewer_support import viewer_screenshot

    img = viewer_screenshot(tiago_run / "run.rrd", tmp_path / "viewer.png")
    h, w = img.shape[:2]
    blue, red, scene = _robot_colours(img)
    assert blue[scene].mean() > 5e-3, "no calibrated robot in the 3-D view"
    assert red[scene].mean() > 1e-3, "no nominal robot in the 3-D view"
    plots = (slice(int(0.05 * h), int(0.27 * h)), slice(int(0.55 * w), int(0.81 * w)))
    colourful = (img.max(axis=2) - img.min(axis=2)) > 0.3
    assert colourful[plots].mean() > 2e-3, "joint readings not drawn"


def test_arc_welder_robot_ends_at_the_tool_tips(report_run):  # noqa: F811
    """Seed 000's D-H arm drawn as capsules too: the calibrated robot's last capsule ends at the
    calibrated tool tip of some measurement, its first starts at the arm's base."""
    from pipeline.models import serial_arm

    rrd = _read(report_run / "run.rrd")
    fit = json.loads((report_run / "identify" / "fit.json").read_text())
    labels = rrd["world/robot/calibrated/links"]["static"]["Capsules3D:labels"]
    t, start, end = _capsule_ends(rrd["world/robot/calibrated/links"], len(labels))
    assert labels[-1].endswith("→ tool") and len(t) > 100  # follows the encoder stream
    base = serial_arm.frames(np.array(fit["x"]), np.zeros((1, 6)))[0, 0, :3, 3]
    np.testing.assert_allclose(start[:, 0], np.broadcast_to(base, start[:, 0].shape), atol=1e-5)
    assert {"world/jig/blocks", "world/robot/nominal/links", "world/instrument"} <= set(rrd)


from report_support import report_run  # noqa: E402,F401  (session fixture)


def test_rerun_viewer_shows_the_arc_welder(report_run, tmp_path):  # noqa: F811
    """The real viewer, headless (Xvfb + Mesa lavapipe), on the arc welder's run: the 3-D view holds
    the calibrated arm (blue capsules) and the nominal one (red)."""
    from viewer_support import viewer_screenshot

    img = viewer_screenshot(report_run / "run.rrd", tmp_path / "viewer.png")
    h, w = img.shape[:2]
    blue, red, scene = _robot_colours(img)
    assert blue[scene].mean() > 5e-3, "no calibrated arm in the 3-D view"
    assert red[scene].mean() > 1e-3, "no nominal arm in the 3-D view"


def _robot_colours(img):
    """(blue mask: the calibrated robot's capsules, red mask: the nominal robot's, the 3-D view's region)."""
    h, w = img.shape[:2]
    R, G, B = img[..., 0], img[..., 1], img[..., 2]
    scene = (slice(int(0.05 * h), int(0.75 * h)), slice(int(0.13 * w), int(0.53 * w)))
    return (B > 0.45) & (B > R + 0.2) & (B > G + 0.1), (R > 0.5) & (R > G + 0.25) & (R > B + 0.25), scene
