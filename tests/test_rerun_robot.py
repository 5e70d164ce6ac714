"""The robot in run.rrd, logged through rerun's URDF support and read back with rerun's own reader
(rerun.chunk.RrdReader): the URDF's links by name, and their frames (placement, the loader's static
transforms, the joint transforms per time step) checked against yourdfpy's forward kinematics of the
calibrated model.urdf, the measured points and the residuals the identify stage wrote; and what the
real rerun viewer (headless) shows: the calibrated robot blue, the nominal one red inside it.

Uses the real TIAGo motion-capture campaign (../shared/real-data/figaroh_tiago_mocap; skips
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

from real_data import real_data  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
REAL = real_data()  # ../shared/real-data (tests/real_data.py)
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


def _assert_both_robots_seen(img: np.ndarray, what: str) -> dict:
    """The calibrated robot's translucent blue body and the nominal robot's red inside it, as a person sees
    them in a 3-D view's screenshot (`viewer_support.robot_in_view`)."""
    from viewer_support import robot_in_view

    r = robot_in_view(img)
    assert max(r["body_extent"]) >= 1 / 4, f"no calibrated {what} in the 3-D view (blue body spans {r['body_extent']})"
    assert min(r["red_extent"]) >= 0.5, f"no nominal {what} along the calibrated one (red inside spans {r['red_extent']})"
    assert r["blue_in_box"] > r["red_in_box"], f"the red nominal {what} hides the blue calibrated one: {r}"
    return r


@needs_tiago
def test_rerun_viewer_shows_the_robot(tiago_run, tmp_path):
    """The real viewer, headless (Mesa's software Vulkan), on the TIAGo run as a user opens it: the 3-D
    view reports nothing wrong and shows the calibrated robot — a translucent blue body spanning a quarter
    of the view or more — with the nominal robot red inside it along at least half its length and width
    (thinner: more blue than red around it); the joint readings are drawn, one colour per joint."""
    from matplotlib.image import imsave
    from viewer_support import Viewer

    with Viewer(tiago_run / "run.rrd") as v:
        views = v.views
        scene = next(n for n, x in views.items() if x.view_class == "3D")
        assert views[scene].reports == [], views[scene].reports
        img = v.screenshot(scene)
        plots = v.screenshot(next(n for n in views if n.startswith("Joint readings")))
    imsave(tmp_path / "scene.png", img)
    _assert_both_robots_seen(img, "robot")
    from matplotlib.colors import rgb_to_hsv

    hsv = rgb_to_hsv(plots)
    hues = np.histogram(hsv[..., 0][(hsv[..., 1] > 0.4) & (hsv[..., 2] > 0.4)], bins=12, range=(0, 1))[0]
    assert (hues > 0.001 * hsv[..., 0].size).sum() >= 4, f"joint readings not drawn in their colours: {hues}"


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
    """The real viewer, headless, on the arc welder's run: its 3-D view shows the calibrated D-H arm
    (translucent blue capsules) with the nominal one (red, thinner) inside it."""
    from viewer_support import Viewer

    with Viewer(report_run / "run.rrd") as v:
        scene = next(n for n, x in v.views.items() if x.view_class == "3D")
        img = v.screenshot(scene)
    _assert_both_robots_seen(img, "arm")
