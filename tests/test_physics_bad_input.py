"""Bad physics input is one line naming the element, exit 2, no traceback, before anything is fitted:
`robocal run` (checked before any stage runs: no run folder results), `robocal calibrate` and the ROS 2
import of a tree — a payload on a link the URDF lacks, gravity terms or a payload on a URDF without
inertials, a coupling naming an unknown joint or forming a cycle (on the command line and in a
recording's campaign metadata), a measured tip that is not in the tree."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import run_cli

import independent_humanoid as hu
import independent_joint_bag as jb

TIPS = ("--tip", "left_hand=lx,ly,lz", "--tip", "right_hand=rx,ry,rz")
COUPLED = ("--coupled", "torso_j3=-torso_j1-torso_j2")


def one_line(r, *needles):
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    for n in needles:
        assert n in r.stderr, (n, r.stderr)


@pytest.fixture(scope="module")
def recs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("physics_bad")
    d = hu.write(tmp / "d", seed=1, n=30, noise_m=2e-4, geometry=False, directions=True)
    joints, links = hu.humanoid()
    (tmp / "bare.urdf").write_text(hu.urdf_text(joints, [hu.Link(lk.name) for lk in links]))
    for name, u in (("ok", d / "humanoid.urdf"), ("bare", tmp / "bare.urdf")):
        r = run_cli("import", "csv", d / "postures.csv", "--urdf", u, "--root", "base", *TIPS, *COUPLED,
                    "--measure", "point", "--out", tmp / f"{name}.mcap")
        assert r.returncode == 0, r.stderr
    return tmp, d


@pytest.mark.parametrize("rec, args, needles", [
    ("ok", ("--payload", "2@nowhere"), ("--payload '2@nowhere'", "link 'nowhere' is not in the URDF")),
    ("bare", ("--physics", "joint-compliance"), ("bare.mcap", "<inertial>", "joint-compliance")),
    ("bare", ("--payload", "2@left_hand"), ("bare.mcap", "<inertial>", "--payload '2@left_hand'")),
    ("ok", ("--physics", "none", "--payload", "2@left_hand"), ("--payload '2@left_hand' needs gravity terms",)),
])
@pytest.mark.parametrize("command", ["run", "calibrate"])
def test_bad_physics_input_is_one_line(recs, command, rec, args, needles):
    tmp, _ = recs
    out = tmp / f"out_{command}_{rec}_{abs(hash(args))}"
    one_line(run_cli(command, tmp / f"{rec}.mcap", "--out", out, *args), *needles)
    assert not (out / "results.json").exists()


@pytest.mark.parametrize("args, needles", [
    (("--coupled", "torso_j3=-torso_j1-nowhere"), ("coupled joint 'torso_j3' names unknown joint 'nowhere'",)),
    (("--coupled", "torso_j3=-torso_j1", "--coupled", "torso_j1=torso_j3"), ("itself coupled", "cycle")),
    (COUPLED + ("--measure-topic", "nowhere=/l"), ("--tip link 'nowhere' is not in the URDF",)),
])
def test_bad_tree_of_a_ros2_bag_is_one_line(recs, tmp_path, args, needles):
    pytest.importorskip("rosbags")
    _, d = recs
    rows = np.loadtxt(d / "postures.csv", delimiter=",", skiprows=1)
    J = len(hu.READ)
    bag = jb.write_bag(tmp_path / "bag", hu.READ, rows[:, :J], rows[:, -J:],
                       {"/l": rows[:, J:J + 3], "/r": rows[:, J + 3:J + 6]})
    topics = ("--measure-topic", "right_hand=/r") + (() if "nowhere=/l" in args else ("--measure-topic", "left_hand=/l"))
    r = run_cli("import", "ros2", bag, "--urdf", d / "humanoid.urdf", "--root", "base", *topics, *args,
                "--out", tmp_path / "x.mcap")
    one_line(r, *needles)
    assert not (tmp_path / "x.mcap").exists()


@pytest.mark.parametrize("coupled, needles", [
    ({"torso_j3": {"terms": {"nowhere": -1.0}}}, ("robocal.campaign", "names unknown joint 'nowhere'")),
    ({"torso_j3": {"terms": {"torso_j1": -1.0}}, "torso_j1": {"terms": {"torso_j3": 1.0}}},
     ("robocal.campaign", "itself coupled")),
    # a factor of 1e308 ended `run` in a traceback in validate's outlier fit: now one line at load
    ({"torso_j3": {"terms": {"torso_j1": 1e308}}}, ("robocal.campaign", "factor 1e+308", "not a physical transmission")),
])
def test_bad_coupling_in_a_recording_is_one_line(recs, tmp_path, coupled, needles):
    """A recording (not the importer) whose campaign couples joints wrongly: calibrate says so in one line."""
    from pipeline.importers.recording import write_urdf_recording
    from pipeline.models import urdf

    _, d = recs
    text = (d / "humanoid.urdf").read_text()
    desc = urdf.parse(text, "base", "left_hand", allow_mimic=True)
    n = 20
    rng = np.random.default_rng(0)
    table = {"joint_positions": rng.uniform(-0.2, 0.2, (n, len(desc.joint_names))), "position": rng.normal(size=(n, 3)),
             "target": np.zeros(n, np.int64)}
    rec = tmp_path / "bad.mcap"
    write_urdf_recording(rec, desc, "point", {"n_targets": 1, "coupled": coupled}, table)
    one_line(run_cli("calibrate", rec, "--out", tmp_path / "c"), *needles)
