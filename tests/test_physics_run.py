"""A whole robot through `robocal run` and `robocal compensate`: the independent humanoid generator
(dual arm, coupled torso, whole-tree gravity, joint compliance at static equilibrium; no robocal code)
imported through the CSV front door, every stage run on the tree model with its physics, and a program
compensated under a payload checked on the generator's true robot."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from conftest import run_cli
from humanoid_import import import_humanoid

import independent_humanoid as hu

pytest.importorskip("pinocchio")

SEED, N = 5, 60
PAYLOAD = {"left_hand": (3.0, (0.0, 0.0, -0.05))}  # kg, centre of mass in the hand's frame (m)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("humanoid_run")
    d = hu.write(tmp / "data", seed=SEED, n=N, noise_m=2e-4, geometry=False)
    rec = tmp / "humanoid.mcap"
    import_humanoid(d, rec)
    out = tmp / "run"
    # every progress line written (not one per 10 s): the short diagnosis of a small tree shows its steps
    r = run_cli("run", rec, "--out", out, "--physics", "joint-compliance", "--folds", "3",
                env={"ROBOCAL_PROGRESS_EVERY_S": "0"})
    return out, r, json.loads((d / "truth.json").read_text())


def test_diagnose_progress_in_the_run_folder_log_off_a_terminal(run):
    """stderr is a pipe here: the diagnosis' progress goes, line by line, to stderr and DIR/diagnose/progress.log —
    the joint-by-joint signatures (which joint of how many), the bootstrap's resamples, the verdict, and a last line."""
    out, r, _ = run
    log = (out / "diagnose" / "progress.log").read_text().splitlines()
    assert all(line.startswith("diagnose: ") and "\r" not in line for line in log)
    joints = [ln for ln in log if ln.startswith("diagnose: signatures: joint ")]
    assert "diagnose: signatures: joint 1 of 14 (torso_j1)" in joints[0] and "joint 14 of 14 (right_j6)" in joints[-1]
    assert any(ln.startswith("diagnose: lack of fit and verdict") for ln in log)
    assert log[-1].startswith("diagnose: done, ")
    assert "diagnose: signatures: joint 1 of 14 (torso_j1)" in r.stderr and "diagnose: done, " in r.stderr
    # identify's model choice names each candidate it scores, k of n
    assert re.search(r"^identify: model choice \(candidate 1 of \d+\): registration \+ ", r.stderr, re.M), r.stderr[-2000:]


def test_run_every_stage_on_a_tree_with_physics(run):
    out, r, truth = run
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr[-3000:]
    res = json.loads((out / "results.json").read_text())
    for stage in ("ingest", "validate", "identify", "observe", "accuracy", "diagnose", "report"):
        assert stage in res["stages"], stage
    assert (out / "run.rrd").stat().st_size > 0
    html = (out / "report.html").read_text()
    assert '<section id="physics">' in html and "geometry only" in html
    phys = res["physics"]
    # the physics terms carry the data: geometry alone is far worse held out, with them near the noise floor
    floor = truth["noise_m"]  # robocal's RMS is per residual component: the noise σ per axis
    assert phys["holdout_with_physics_m"] < 1.5 * floor
    assert phys["holdout_geometry_only_m"] > 3 * phys["holdout_with_physics_m"]
    by = {t["joint"]: t for t in phys["terms"] if t["family"] == "joint-compliance"}
    for j in ("torso_j1", "torso_j2"):  # the best-loaded joints: stiffness within 3σ of the truth
        c_true = 1 / truth["stiffness_Nm_per_rad"][j]
        z = (by[j]["compliance_rad_per_Nm"] - c_true) / by[j]["compliance_std_rad_per_Nm"]
        assert abs(z) < 3, (j, z)
        assert by[j]["reading"].startswith(f"{j}: stiffness ") and "N·m/rad ±" in by[j]["reading"]


def _targets(tmp, truth_obj, k: int = 6):
    """Targets of the left hand's marker on the true robot carrying PAYLOAD, with the read joints as hints."""
    rng = np.random.default_rng(99)
    q = hu.postures(rng, k)
    y = hu.measure(truth_obj, q, 0.0, rng, payload=PAYLOAD)["left"]
    cols = ["x", "y", "z"] + [f"q_{j}" for j in hu.READ]
    rows = np.column_stack([y] + [q[j] for j in hu.READ])
    path = tmp / "targets.csv"
    path.write_text(",".join(cols) + "\n" + "\n".join(",".join(f"{v:.12g}" for v in r) for r in rows) + "\n")
    return path, y


def _reached(truth_obj, program):
    """The true robot's left marker (payload carried) at the program's joint readings."""
    import pyarrow.csv as pacsv

    t = pacsv.read_csv(program)
    assert set(t.column("status").to_pylist()) == {"ok"}
    q = {j: np.asarray(t.column(f"q_{j}").to_numpy(), float) for j in hu.READ}
    return hu.measure(truth_obj, q, 0.0, np.random.default_rng(0), payload=PAYLOAD)["left"]


def test_compensation_under_payload_uses_the_physics(run, tmp_path):
    out, r, _ = run
    assert r.returncode == 0, r.stderr[-2000:]
    truth_obj = hu.default_truth(np.random.default_rng(SEED), geometry=False)
    targets, y = _targets(tmp_path, truth_obj)
    err = {}
    for mode in ("auto", "none"):
        prog = tmp_path / f"program_{mode}.csv"
        c = run_cli("compensate", out, "--targets", targets, "--out", prog, "--payload", "3@left_hand:0,0,-0.05",
                    "--physics", mode)
        assert c.returncode == 0, c.stderr
        err[mode] = float(np.sqrt(np.mean(np.sum((_reached(truth_obj, prog) - y) ** 2, axis=1))))
    # the deflection of the torso and shoulder under 3 kg is mm; the physics compensation takes it out
    assert err["auto"] < 0.5e-3 and err["auto"] < 0.25 * err["none"], err


@pytest.mark.parametrize("args, message", [
    (("--payload", "2@no_such_link"), "no_such_link"),
    (("--payload", "2kg@left_hand"), "--payload"),
    (("--physics", "maybe"), "--physics"),
    (("--tip", "nose"), "nose"),
])
def test_compensate_bad_input_one_line(run, tmp_path, args, message):
    out, r, _ = run
    assert r.returncode == 0, r.stderr[-2000:]
    truth_obj = hu.default_truth(np.random.default_rng(SEED), geometry=False)
    targets, _ = _targets(tmp_path, truth_obj, k=2)
    c = run_cli("compensate", out, "--targets", targets, "--out", tmp_path / "p.csv", *args)
    assert c.returncode == 2 and message in c.stderr and "Traceback" not in c.stderr, c.stderr
    assert len(c.stderr.strip().splitlines()) == 1, c.stderr
