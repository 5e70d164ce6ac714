"""What the diagnosis advises about structure it locates along a joint but cannot name: along a joint whose
gravity load is a smooth function of its own reading (a shoulder lifting the arm, a torso pitch), the structure
may be compliance or backlash under that load, not a transmission error.  The load comes from the whole tree
(Pinocchio) of the independent humanoid generator's URDF."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import run_cli

import independent_humanoid as hu

pytest.importorskip("pinocchio")


@pytest.fixture(scope="module")
def model_table(tmp_path_factory):
    from pipeline.recording.reader import read_recording
    from pipeline.systems import urdf_robot

    tmp = tmp_path_factory.mktemp("advice")
    d = hu.write(tmp / "data", seed=4, n=60, geometry=False)
    rec = tmp / "h.mcap"
    r = run_cli("import", "csv", d / "postures.csv", "--urdf", d / "humanoid.urdf", "--root", "base",
                "--tip", "left_hand=lx,ly,lz", "--tip", "right_hand=rx,ry,rz",
                "--coupled", "torso_j3=-torso_j1-torso_j2", "--measure", "point", "--out", rec)
    assert r.returncode == 0, r.stderr
    return urdf_robot.load(read_recording(rec), "none")


def test_load_tracking_joints_get_load_dependent_advice(model_table):
    from pipeline.diagnose.adapters import urdf_robot as du
    from pipeline.diagnose.verdict.checks import advice_for

    model, table = model_table
    advice = du.load_advice(model, table)
    q, tau = np.asarray(table["joint_positions"]), du.load_torques(model, table)
    names = list(model.kin.joint_names)
    r2 = {n: du.load_tracking(q[:, j], tau[:, j]) for j, n in enumerate(names)}
    # the shoulders lift whole arms: their load follows their own angle; the wrists' barely does
    assert r2["left_j1"] > 0.8 and r2["right_j1"] > 0.8 and r2["left_j6"] < 0.5
    for n in names:
        text = advice(f"q_{n}")
        if r2[n] >= du.LOAD_R2:
            assert text.startswith("load-dependent (compliance/backlash under gravity)") and n in text
        else:
            assert text is None and "transmission" in advice_for(f"q_{n}")
    assert advice("q_left_j1→left_j2") is None and advice("time_since_start_s") is None


@pytest.mark.parametrize("seed", range(5))
def test_load_tracking_is_the_share_a_smooth_function_explains(seed):
    """R² against a direct regression: 1 for a load that is a function of the angle, ≈ 0 for an unrelated one."""
    from pipeline.diagnose.adapters.urdf_robot import load_tracking

    rng = np.random.default_rng(seed)
    q = rng.uniform(-1.5, 1.5, 200)
    assert load_tracking(q, 30 * np.sin(q) + 5) == pytest.approx(1.0, abs=1e-9)
    assert load_tracking(q, rng.normal(0, 10, q.size)) < 0.1
    assert load_tracking(q, np.full(q.size, 3.0)) == 0.0
