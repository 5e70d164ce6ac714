"""Thin data judged by information, not row counts: repeated rows add nothing, a 50-contact
campaign that reaches the noise floor is not `insufficient`, advice counts what a full model
needs.  Data from yourdfpy's kinematics (`yourdfpy_points`) and the arc-welder simulator."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import run_cli
from pipeline.accuracy import information as I
from pipeline.validate.checks import check_duplicates
from r6_robot import BARE_URDF
from yourdfpy_points import campaign, write_csv


@pytest.fixture(scope="module")
def one_pose(tmp_path_factory):
    """60 identical rows (one robot pose) imported from CSV and calibrated."""
    d = tmp_path_factory.mktemp("onepose")
    q, p = campaign(1, seed=4)
    csv = write_csv(d / "same.csv", np.repeat(q, 60, axis=0), np.repeat(p, 60, axis=0))
    (d / "r6.urdf").write_text(BARE_URDF)
    imp = run_cli("import", "csv", csv, "--urdf", d / "r6.urdf", "--root", "b", "--tip", "l6", "--measure", "point",
                  "--out", d / "same.mcap")
    assert imp.returncode == 0, imp.stderr
    cal = run_cli("calibrate", d / "same.mcap", "--out", d / "cal", "--folds", "2")
    return d, cal


def test_repeated_rows_are_insufficient_and_state_no_accuracy_better_than_the_prior(one_pose):
    d, cal = one_pose
    assert cal.returncode == 0, cal.stderr[-2000:]
    doc = json.loads((d / "cal" / "results.json").read_text())
    acc = doc["accuracy"]
    assert doc["status"] == "insufficient"
    assert "1 distinct configuration" in acc["reason"] and "repeated rows add no information" in acc["reason"]
    info = acc["information"]
    assert info["n_measurements"] == 60 and info["n_distinct"] == 1 and info["dof"] <= 0
    # the fit interpolates its one point: the stated 1σ is the prior's, not the 1e-17 m of a zero residual
    assert acc["map_rms_1sigma_m"] >= 0.99 * acc["map_uncalibrated_rms_1sigma_m"] > 1e-4
    # advice counts the full model (the rank over configurations within the joint limits), not the 3 fitted here
    assert info["identified_full_model"] > 20
    more = int(acc["advice"].split("record at least ")[1].split()[0])
    assert more * 3 + 3 >= 3 * info["identified_full_model"]
    assert "0.0000 mm" not in cal.stderr and "predicted 3-D point accuracy" not in cal.stderr


def test_validate_names_rows_that_repeat_a_configuration_and_reading():
    bodies = [{"timestamp_ns": i, "joint_positions": [0.1, 0.2], "position": [1.0, 2.0, 3.0]} for i in range(6)]
    bodies.append({"timestamp_ns": 99, "joint_positions": [0.3, 0.2], "position": [1.0, 2.0, 3.5]})
    c = check_duplicates("/measure/point", bodies, np.array([b["timestamp_ns"] for b in bodies]))
    assert c.status == "warn" and c.records == [1, 2, 3, 4, 5]
    assert "2 distinct of 7" in c.message and "adds no information" in c.message


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 5))
def test_repeating_rows_changes_no_information(seed, copies):
    """Distinct measurements, residual degrees of freedom and condition do not change when every row
    is repeated; the rank of the point Jacobian bounds the identified set."""
    rng = np.random.default_rng(seed)
    n, k, P = 12, 3, 7
    Jm = rng.normal(size=(n * k, P))
    Jp = rng.normal(size=(20, 3, P))
    free = np.ones(P, bool)
    names = [f"p{i}" for i in range(P)]
    a = I.information(Jm, free, k, Jp, names)
    rep = np.tile(Jm.reshape(n, k, P), (copies, 1, 1)).reshape(-1, P)
    b = I.information(rep, free, k, Jp, names)
    assert (a.n_distinct, a.dof, a.p_full) == (b.n_distinct, b.dof, b.p_full) == (n, n * k - P, P)
    assert b.n_measurements == copies * n
    assert np.isclose(a.condition, b.condition, rtol=1e-6)


# ----- the arc welder: 50 contacts are enough, 16 are not, and the advice counts 81 ---------------
def _arc(n: int, seed: int):
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from bench_accuracy_honesty import _evaluate
    from pipeline.plan.arc_welder import measured
    from pipeline.systems import arc_welder as aw

    model, table = measured(n, seed, random_errors=True)
    truth = aw.random_truth(aw.nominal_arm(), np.random.default_rng(seed + 1_000_003)).vector()
    return _evaluate(model, table, truth, folds=5 if n >= 40 else 0)


@pytest.mark.parametrize("seed", [0, 2])
def test_fifty_contacts_reach_the_noise_floor_and_pass(seed):
    r = _arc(50, seed)
    assert r["status"] == "pass", r["reason"]
    ratio = np.sqrt(np.mean(r["true"] ** 2)) / np.sqrt(np.mean(r["pred"] ** 2))
    assert 0.6 < ratio < 1.4 and np.mean(r["true"] <= r["b95"]) >= 0.9


def test_sixteen_contacts_advice_counts_the_full_model():
    r = _arc(16, 0)
    assert r["status"] == "insufficient"
    assert "16 residuals for 16 identified parameters" in r["reason"]
    assert "identifies 27 of 42 parameters and needs about 81 distinct residuals" in r["advice"]
    assert "record at least 65 more" in r["advice"]


def test_urdf_robot_stated_accuracy_matches_the_truth_over_seeds():
    """The benchmark's URDF case on a bounded number of seeds: the true 3-D error at 100 new
    configurations against the stated 1σ (pooled over seeds) and the 95 % bound's coverage of the points
    (`benchmarks/bench_accuracy_honesty.py --systems urdf --seeds 20` for the full figure)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from bench_accuracy_honesty import urdf_robot

    runs = [urdf_robot(s) for s in range(4)]
    per = [np.sqrt(np.mean(r["true"] ** 2)) / np.sqrt(np.mean(r["pred"] ** 2)) for r in runs]
    assert 0.75 < np.sqrt(np.mean(np.square(per))) < 1.3, per
    assert min(np.mean(r["true"] <= r["b95"]) for r in runs) >= 0.9
    assert all(r["status"] == "pass" for r in runs)
