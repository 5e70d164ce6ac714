"""`robocal plan camera`: D-optimal robot poses for a camera on a 6R arm with a spherical wrist.

The planned images recover a simulated truth better than random sets of as many reachable
candidate images (smaller stated σ and smaller true error; detections projected at the truth by
OpenCV), and the planned campaign, executed on the simulated true robot — images rendered by
OpenCV at the campaign's joints, detected by `robocal import images` — sees the whole board in
every image."""

import json

import numpy as np
import pytest
from conftest import run_cli
from r6_robot import WRIST_URDF

from pipeline.camera.targets import parse as parse_target
from pipeline.identify.complexity import fixed_for
from pipeline.measurements.camera import CameraModel
from pipeline.models.urdf import parse
from pipeline.models.urdf_arm import UrdfArm
from pipeline.plan import camera as pc
from pipeline.plan import camera_check as cc

TARGET = "chessboard:9x6:0.03"
HOME = np.array([0.0, 0.3, -0.5, 0.0, 0.8, 0.0])


def _model(mount="tip"):
    return CameraModel(UrdfArm(parse(WRIST_URDF, "base", "tool")), mount=mount, n_dist=5, image_size=(640, 480))


@pytest.mark.parametrize("mount,seed", [("tip", 0), ("world", 1)])
def test_planned_images_beat_random_ones_on_a_simulated_truth(mount, seed):
    model, tgt = _model(mount), parse_target(TARGET)
    setup = pc.Setup(tgt, np.array([520.0, 520, 319.5, 239.5, 0, 0, 0, 0, 0]), HOME, 0.5)
    x = pc.nominal(model, setup)
    cand = pc.candidate_views(model, x, setup, 200, np.random.default_rng(seed))
    fixed = fixed_for(model, ["registration", "joint offsets"])
    sel, free = pc.plan_images(model, x, cand, tgt, 10, fixed)
    names = np.array(model.parameter_names())
    for p in ("camera.fx", "camera.k1", "tool.x", "tool.roll", "j2.offset", "j3.offset"):
        assert p in names[free], f"{p} is not planned for"
    assert "tool.yaw" in names[free] or "j6.offset" in names[free]  # one of the two (same rotation)
    assert np.all(cand.border_px[sel.index] >= 30)  # every corner inside the nominal image by the margin
    truth = cc.true_cell(model, x, np.random.default_rng(seed + 10), tuple(names[~free]))
    r = cc.compare(model, truth, cand.q, sel.index, tgt, free, n_random=8, noise_px=0.1, seed=seed, draws=3)
    assert len(r["parameters"]) >= 20
    # stated σ: geometric mean over the parameters relative to the median random set's σ
    assert r["sigma_ratio_planned"] < 0.9 * np.median(r["sigma_ratio_random"]), r
    # true error (in the median random σ): planned below the median random set
    assert r["error_planned"] < np.median(r["error_random"]), r
    # the planned fits are honest: their RMS true errors within 3 of their stated σ
    z = np.array(r["planned_error"]) / np.array(r["planned_sigma"])
    assert np.all(z < 3), dict(zip(r["parameters"], z.round(1)))


def test_the_planned_campaign_sees_the_whole_board_on_the_true_robot(tmp_path):
    from pipeline.plan.campaign import read_pose
    from pipeline.recording.reader import read_recording
    from pipeline.systems import urdf_robot

    urdf = tmp_path / "six.urdf"
    urdf.write_text(WRIST_URDF)
    plan = tmp_path / "P.json"
    res = run_cli("plan", "camera", "--urdf", urdf, "--root", "base", "--tip", "tool", "--target", TARGET,
                  "--home", ",".join(map(str, HOME)), "--focal-px", "520", "--candidates", "150", "--select", "8",
                  "--out", plan)
    assert res.returncode == 0, res.stderr
    doc = json.loads(plan.read_text())
    assert doc["kind"] == "robocal.campaign" and doc["measurement"] == "pose" and doc["instrument"] == "camera"
    assert len(doc["measurements"]) == 8 and len(set(m["candidate"] for m in doc["measurements"])) == 8
    model, tgt = _model(), parse_target(TARGET)
    q = read_pose(plan, "urdf", model.kin.joint_names)  # the campaign as a robot runs it: joints per image
    assert np.allclose(q, np.array([m["joints_rad"] for m in doc["measurements"]]))
    res = run_cli("simulate", "camera", "--campaign", plan, "--out", tmp_path / "images", "--truth", tmp_path / "T.json",
                  "--seed", "3")
    assert res.returncode == 0, res.stderr
    csv = (tmp_path / "images" / "joints.csv").read_text().splitlines()
    assert len(csv) == 9 and np.allclose(np.array([r.split(",")[1:] for r in csv[1:]], float), q)  # at the planned joints
    truth = json.loads((tmp_path / "T.json").read_text())["parameters"]
    x = pc.nominal(model, pc.Setup(tgt, np.array([520.0, 520, 319.5, 239.5, 0, 0, 0, 0, 0]), HOME, 0.5))
    held = [n for n in model.parameter_names() if n not in doc["free_parameters"]]
    assert held and all(truth[n] == x[model.parameter_names().index(n)] for n in held)  # errors only where planned for
    assert abs(truth["camera.k1"] + 0.2) < 1e-12  # a real lens
    res = run_cli("import", "images", tmp_path / "images", "--target", TARGET, "--joints",
                  tmp_path / "images" / "joints.csv", "--urdf", urdf, "--root", "base", "--tip", "tool",
                  "--distortion-terms", "5", "--workers", "1", "--out", tmp_path / "rec.mcap")
    assert res.returncode == 0, res.stderr
    _, data = urdf_robot.load(read_recording(tmp_path / "rec.mcap"))
    counts = np.bincount(np.asarray(data["image"]))
    assert counts.size == 8 and np.all(counts == tgt.n_corners), counts  # the whole board in every image


def test_bad_home_is_one_line(tmp_path):
    urdf = tmp_path / "six.urdf"
    urdf.write_text(WRIST_URDF)
    res = run_cli("plan", "camera", "--urdf", urdf, "--root", "base", "--tip", "tool", "--target", TARGET,
                  "--home", "0,0.3,-0.5", "--out", tmp_path / "P.json")
    assert res.returncode == 2 and "--home" in res.stderr and "6 joint positions" in res.stderr
    assert "Traceback" not in res.stderr and not (tmp_path / "P.json").exists()
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "mine.png").write_bytes(b"x")
    plan = tmp_path / "urdf_plan.json"  # a campaign that is not a camera's cannot be rendered
    plan.write_text(json.dumps({"kind": "robocal.campaign", "version": 1, "system": "urdf", "measurement": "pose",
                                "joint_names": ["j1"], "stage": 1, "stages": 1, "measurements": [{"index": 0}]}))
    res = run_cli("simulate", "camera", "--campaign", plan, "--out", tmp_path / "imgs")
    assert res.returncode == 2 and "not a camera campaign" in res.stderr and "Traceback" not in res.stderr
    res = run_cli("simulate", "camera", "--campaign", plan, "--out", tmp_path / "full")
    assert res.returncode == 2 and "not an empty folder" in res.stderr
    assert [p.name for p in (tmp_path / "full").iterdir()] == ["mine.png"]  # never over files robocal did not create
