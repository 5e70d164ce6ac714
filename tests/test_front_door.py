"""Nonsense is refused at the door, as a user types it: `robocal import csv` on the real TIAGo
motion-capture table (../shared/real-data/figaroh_tiago_mocap), `robocal run` with a payload,
`robocal import ros2` of a bag of TIAGo's joints, `robocal compensate` — each case found by
independent fuzzing (all accepted and calibrated before, statuses `warn` at most) is one line naming
the option or file and the element, exit 2, no traceback, nothing written.  The rules behind them:
docs/reference/bad-input.md ("Nonsense at the door")."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import run_cli

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "real-data" / "figaroh_tiago_mocap"
CSV, URDF = REAL / "qualysis_base_hand_calibration.csv", REAL / "tiago_48_schunk.urdf"
pytestmark = pytest.mark.skipif(not CSV.is_file(), reason="../shared/real-data/figaroh_tiago_mocap is absent (the "
                                "real TIAGo data are not shipped with the repository)")
CHAIN = ("--root", "base_footprint", "--measure", "point")
TIP = CHAIN + ("--tip", "wrist_ft_tool_link")
MARKER = TIP + ("--position-cols", "x1,y1,z1")


def refused(r, *needles: str) -> str:
    assert r.returncode == 2, (r.returncode, r.stdout[-500:], r.stderr)
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    for n in needles:
        assert n in r.stderr, (n, r.stderr)
    return r.stderr


@pytest.fixture(scope="module")
def tiago(tmp_path_factory) -> Path:
    """The TIAGo table imported as the guide does (marker 1 at the tool link)."""
    d = tmp_path_factory.mktemp("door")
    r = run_cli("import", "csv", CSV, "--urdf", URDF, *MARKER, "--out", d / "tiago.mcap")
    assert r.returncode == 0, r.stderr
    return d / "tiago.mcap"


@pytest.mark.parametrize("args, needles", [
    (TIP + ("--position-cols", "x1,x1,z1"), ("--position-cols 'x1,x1,z1'", "column 'x1' is given twice")),
    (CHAIN + ("--tip", "wrist_ft_tool_link=x1,x1,x1"), ("--tip wrist_ft_tool_link=x1,x1,x1", "'x1' is given twice")),
    (TIP + ("--position-cols", "x1,y1,arm_1_joint"), ("column 'arm_1_joint' is already the reading of joint",)),
    (CHAIN + ("--tip", "wrist_ft_tool_link=x1,y1,z1", "--tip", "arm_7_link=x1,y1,z1"),
     ("--tip arm_7_link=x1,y1,z1", "column 'x1' is already the x of --tip wrist_ft_tool_link")),
    (MARKER + ("--coupled", "arm_7_joint=arm_6_joint"),
     ("qualysis_base_hand_calibration.csv", "column 'arm_7_joint'", "--coupling-wins")),
    (MARKER + ("--coupled", "torso_lift_joint=arm_1_joint", "--coupling-wins"),
     ("--coupled 'torso_lift_joint=arm_1_joint'", "prismatic", "revolute", "[m/rad]")),
    (CHAIN + ("--tip", "wrist_ft_tool_link=x1,y1,z1", "--position-cols", "x2,y2,z2"),
     ("--position-cols 'x2,y2,z2' and --tip LINK=X,Y,Z cannot be combined",)),
    (MARKER + ("--coupled", "arm_7_joint=1e308*arm_1_joint", "--coupling-wins"),
     ("--coupled 'arm_7_joint=1e308*arm_1_joint'", "factor 1e+308", "beyond ±100 rad/rad")),
    (MARKER + ("--coupled", "arm_7_joint=1e7*arm_1_joint", "--coupling-wins"), ("factor 1e+07",)),
])
def test_nonsense_import_is_one_line_and_writes_nothing(tmp_path, args, needles):
    out = tmp_path / "x.mcap"
    refused(run_cli("import", "csv", CSV, "--urdf", URDF, *args, "--out", out), *needles)
    assert not out.exists()


def test_a_coupling_with_its_unit_where_the_coupling_wins_is_a_documented_success(tmp_path):
    """The way out each refusal names works: the lift driven by arm_1 in m/rad, replacing its column."""
    out = tmp_path / "x.mcap"
    r = run_cli("import", "csv", CSV, "--urdf", URDF, *MARKER, "--coupled", "torso_lift_joint=0.01[m/rad]*arm_1_joint",
                "--coupling-wins", "--out", out)
    assert r.returncode == 0, r.stderr
    assert "of 7 joints" in r.stderr  # the lift is driven, no longer read


@pytest.mark.parametrize("payload, needles", [
    ("2@arm_7_link:0,0,1e9", ("--payload '2@arm_7_link:0,0,1e9'", "centre of mass 1e+09 m", "farther than the robot")),
    ("5000@arm_7_link", ("5000 kg is more than the whole robot",)),
    ("2@base_link", ("link 'base_link' hangs from none of the measured chains' movable joints",)),
])
def test_a_payload_beyond_the_robot_is_refused_before_any_stage(tiago, tmp_path, payload, needles):
    refused(run_cli("run", tiago, "--out", tmp_path / "run", "--payload", payload), str(tiago), *needles)
    assert not (tmp_path / "run" / "ingest").exists()


def test_a_bag_measuring_1e300_or_coupling_a_joint_it_reads_is_refused(tmp_path):
    """`import ros2` applies the ±1e6 bound `import csv` does (one module, `importers.bounds`), and the
    rule that a --coupled joint has no readings of its own unless --coupling-wins."""
    pytest.importorskip("rosbags")
    import independent_joint_bag as jb

    names = ["torso_lift_joint"] + [f"arm_{i}_joint" for i in range(1, 8)]
    rows = np.loadtxt(CSV, delimiter=",", skiprows=1)[:8]
    markers = rows[:, :3].copy()
    markers[3, 0] = 1e300
    bag = jb.write_bag(tmp_path / "bag", names, rows[:, 12:], np.ones((8, 8)), {"/mocap/tool": markers})
    out = tmp_path / "x.mcap"
    args = ("import", "ros2", bag, "--urdf", URDF, *TIP[:2], "--tip", "wrist_ft_tool_link", "--out", out)
    refused(run_cli(*args), "topic /mocap/tool: record 3: position x: 1e+300 is beyond ±1e+06")
    markers[3, 0] = rows[3, 0]
    bag = jb.write_bag(tmp_path / "bag2", names, rows[:, 12:], np.ones((8, 8)), {"/mocap/tool": markers})
    refused(run_cli(*args[:2], bag, *args[3:], "--coupled", "arm_7_joint=arm_6_joint"),
            "topic /joint_states: joint 'arm_7_joint' is given to --coupled but the JointStates carry its readings",
            "--coupling-wins")
    assert not out.exists()


def test_payload_off_the_chain_is_one_warning_and_compensate_refuses_degrees_and_unknown_columns(tiago, tmp_path):
    """The head hangs from the torso lift: physics the tree's gravity takes — one warning line, and the run
    goes on; on that run, `compensate` refuses a target table with joints in degrees or an unknown column."""
    run = tmp_path / "run"
    r = run_cli("run", tiago, "--out", run, "--stages", "ingest,validate,identify", "--payload", "2@head_2_link")
    assert r.returncode == 0, r.stderr
    warn = [ln for ln in r.stderr.splitlines() if "head_2_link" in ln]
    assert len(warn) == 1 and "on no measured chain" in warn[0] and "loads torso_lift_joint" in warn[0], r.stderr
    joints = ["torso_lift_joint"] + [f"arm_{i}_joint" for i in range(1, 8)]
    deg = tmp_path / "deg.csv"
    deg.write_text("x,y,z," + ",".join(f"q_{j}" for j in joints) + "\n0.4,0.5,0.4,0.2,70,-25,-38,116,-27,35,-29\n")
    unknown = tmp_path / "unknown.csv"
    unknown.write_text("x,y,z,speed\n0.4,0.5,0.4,3\n")
    out = tmp_path / "program.csv"
    refused(run_cli("compensate", run, "--targets", deg, "--out", out), "deg.csv", "column q_arm_1_joint",
            "70 is far outside", "degrees given as radians?")
    refused(run_cli("compensate", run, "--targets", unknown, "--out", out), "unknown.csv",
            "column 'speed' is not a target column")
    assert not out.exists()
