"""D-optimal planning for a URDF robot measured by 3-D points (the generic `plan` over the generic
measurement model): the planned set beats the median of random sets of the same size at new
configurations, on a truth with errors the plan did not know."""

from __future__ import annotations

import numpy as np
from r6_robot import BARE_URDF as URDF  # noqa: E402

from pipeline.identify.model import take
from pipeline.measurements.point import PointModel
from pipeline.models import urdf, urdf_arm
from pipeline.plan.select import holdout_rms, plan
from pipeline.plan.urdf_robot import configurations, table_at


def test_planned_points_beat_random_sets():
    arm = urdf_arm.UrdfArm(urdf.parse(URDF, "b", "l6"))
    model = PointModel(arm)
    rng = np.random.default_rng(3)
    truth = model.nominal() + rng.normal(0, 1e-3, len(model.nominal()))
    truth[model.parameter_names().index("tool.z")] = 0.05
    cand = table_at(model, truth, configurations(arm, 400, 1))
    cand["position"] = cand["position"] + rng.normal(0, 5e-5, cand["position"].shape)
    test = table_at(model, truth, configurations(arm, 300, 2))
    p = plan(model, cand, 30)
    planned = holdout_rms(model, take(cand, p.selection.index), test)
    random = [holdout_rms(model, take(cand, np.sort(rng.choice(400, 30, replace=False))), test) for _ in range(7)]
    assert planned < np.median(random), (planned, random)
    assert planned < 1e-4  # at new configurations: near the 50 µm measurement noise


def test_plan_urdf_cli_writes_an_executable_campaign(tmp_path):
    """`robocal plan urdf`: a schema-valid pose campaign of the chain's joints (URDF names, within the
    limits, the selected candidates), and on a simulated truth the planned set's true 3-D tool-point
    error at new configurations beats every one of 5 random sets of the same size."""
    import json

    from conftest import run_cli

    from pipeline.recording.schemas import validator

    robot = tmp_path / "r6.urdf"
    robot.write_text(URDF)
    out = tmp_path / "plan.json"
    r = run_cli("plan", "urdf", "--urdf", robot, "--root", "b", "--tip", "l6", "--measure", "point",
                "--candidates", "400", "--select", "25", "--seed", "1", "--check", "5", "--out", out)
    assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    assert not list(validator("campaign").iter_errors(doc))
    assert doc["system"] == "urdf" and doc["instrument"] == "point" and doc["urdf"]["tip"] == "l6"
    assert doc["joint_names"] == ["j1", "j2", "j3", "j4", "j5", "j6"]
    q = np.array([m["joints_rad"] for m in doc["measurements"]])
    assert q.shape == (25, 6) and len({m["candidate"] for m in doc["measurements"]}) == 25
    arm = urdf_arm.UrdfArm(urdf.parse(URDF, "b", "l6"))
    lo, hi = np.nan_to_num(arm.lower, nan=-np.inf), np.nan_to_num(arm.upper, nan=np.inf)
    assert np.all((q >= lo - 1e-12) & (q <= hi + 1e-12))
    c = doc["check"]
    assert c["planned_rank_among_random"] == 0, c
    assert c["planned_holdout_rms_m"] < 2e-4  # true 3-D error, with 50 µm noise on 25 points


def test_plan_urdf_cli_bad_input(tmp_path):
    from conftest import run_cli

    robot = tmp_path / "r6.urdf"
    robot.write_text(URDF)
    for args, words in [(("--measure", "plane"), "'plane' is not one of 'point', 'pose'"), ((), "--urdf ROBOT.urdf --root LINK --tip LINK"),
                        (("--candidates", "10", "--select", "20"), "cannot select 20 of 10 candidates")]:
        extra = ("--urdf", robot, "--root", "b", "--tip", "l6") if args else ()
        r = run_cli("plan", "urdf", *extra, *args, "--out", tmp_path / "p.json")
        assert r.returncode != 0 and words in r.stderr and "Traceback" not in r.stderr, r.stderr
        assert not (tmp_path / "p.json").exists()
