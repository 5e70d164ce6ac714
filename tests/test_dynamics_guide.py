"""The dynamics guide's commands on FIGAROH's real TIAGo excitation run, run as docs/guide/dynamics.md prints them
(every ```sh block, in page order, with bash in a folder laid out like the repository's root and
../shared/real-data beside it): import the frozen split → `robocal run` → `robocal evaluate` (below FIGAROH's
held-out figures on every scored joint and pooled, the URDF as drawn at FIGAROH's own nominal figure, 57 base
parameters, physically consistent bodies), `robocal diagnose` on the recording, `robocal plan excitation` (a
lower condition number than a random Fourier trajectory; the CSV and the JointTrajectory bag), `robocal simulate
dynamics` executing that plan with two injected effects that the run names near their truth, and the bounded
benchmarks.  Skipped, saying so, where the real data are absent.
"""

import json
import os
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
from real_data import real_data

REPO = Path(__file__).resolve().parents[1]
REAL = real_data()  # ../shared/real-data (tests/real_data.py)
GUIDE = REPO / "docs" / "guide" / "dynamics.md"
LINKED = (".venv", "benchmarks", "recordings", "schemas", "docs", "tests")
# FIGAROH 1.0.2's TIAGo identification fitted on rows [921, 4900), predicting [4900, 6791) without refitting,
# scored on the raw converted effort at the recorded rate (N·m): benchmarks/figaroh_tiago_dynamics.py split
FIGAROH_SPLIT = {"arm_1_joint": 1.451, "arm_2_joint": 3.127, "arm_3_joint": 1.385, "arm_4_joint": 1.442}
FIGAROH_POOLED, FIGAROH_POOLED_2_4, NOMINAL_POOLED = 1.992, 2.143, 5.410
# the page's commands take ≈ 130 s CPU; on a box shared with other jobs their wall time can pass the suite's 600 s
pytestmark = pytest.mark.timeout(1800)


def sh_blocks() -> list[str]:
    """The page's TIAGo blocks (the TX40's, on a log outside the shared folder: tests/test_dynamics_tx40.py)."""
    return [b for b in re.findall(r"^```sh\n(.*?)^```", GUIDE.read_text(), flags=re.S | re.M)
            if "ROBOCAL_TX40" not in b]


@pytest.fixture(scope="module")
def guide(tmp_path_factory):
    if not (REAL / "figaroh_tiago_dynamics" / "dynamic" / "tiago_effort.csv").is_file():
        pytest.skip("../shared/real-data/figaroh_tiago_dynamics is absent: the dynamics guide's TIAGo commands not run")
    root = tmp_path_factory.mktemp("guide")
    repo = root / "repo"
    repo.mkdir()
    for name in LINKED:
        (repo / name).symlink_to(REPO / name)
    (root / "shared").mkdir()
    (root / "shared" / "real-data").symlink_to(REAL)
    env = {k: v for k, v in os.environ.items() if k != "VIRTUAL_ENV"}
    env["PATH"] = os.pathsep.join([str(REPO / ".venv" / "bin"), env.get("PATH", "")])
    outs = []
    for body in sh_blocks():
        r = subprocess.run(["bash", "-e", "-o", "pipefail", "-c", body], cwd=repo, env=env, capture_output=True,
                           text=True, timeout=1800)
        assert r.returncode == 0 and "Traceback" not in r.stderr, f"{body}\n{r.stdout}\n{r.stderr}"
        outs.append(r)
    return repo, outs


def test_the_guide_shows_the_frozen_split_and_every_command():
    text = "\n".join(sh_blocks())
    assert "/work/" not in text and "R=../shared/real-data/figaroh_tiago_dynamics" in text
    for cmd in ("robocal import csv", "train:921:4900 test:4900:6791", "robocal run tiago-dyn-train.mcap",
                "robocal evaluate runs/tiago-dyn tiago-dyn-test.mcap", "robocal diagnose tiago-dyn-train.mcap",
                "robocal plan excitation", "robocal simulate dynamics", "benchmarks/bench_dynamics.py",
                "benchmarks/bench_dynamics_diagnosis.py"):
        assert cmd in text, cmd


def test_split_beats_figaroh_on_every_scored_joint_and_pooled(guide):
    repo, _ = guide
    r = json.loads((repo / "runs/tiago-dyn-eval/evaluation.json").read_text())["recordings"][0]
    for j, v in FIGAROH_SPLIT.items():
        assert r["rms_joint_Nm"][j] < v, (j, r["rms_joint_Nm"][j], v)
    assert r["rms_pooled_Nm"] < FIGAROH_POOLED
    assert np.sqrt(np.mean([r["rms_joint_Nm"][f"arm_{k}_joint"] ** 2 for k in (2, 3, 4)])) < FIGAROH_POOLED_2_4
    assert abs(r["nominal_rms_pooled_Nm"] - NOMINAL_POOLED) < 0.05  # same constants, same figure as FIGAROH's
    ident = repo / "runs/tiago-dyn/identify"
    fit = json.loads((ident / "fit.json").read_text())
    assert fit["n_identifiable"] == 57 and all(fit["consistent"]["bodies_consistent"])
    for name in ("model.urdf", "dynamics.yaml", "torques.parquet"):
        assert (ident / name).is_file(), name
    assert (repo / "runs/tiago-dyn/report.html").is_file() and (repo / "runs/tiago-dyn/run.rrd").is_file()


def test_the_diagnosis_states_its_held_out_effect_and_what_it_cannot_see(guide):
    repo, _ = guide
    proxies = []
    for doc in (repo / "runs/tiago-dyn/diagnose/diagnosis.json", repo / "runs/tiago-dyn-diagnose/diagnosis.json"):
        d = json.loads(doc.read_text())
        assert d["status"] in ("clean", "explained", "partially_explained", "unexplained")
        assert d["holdout_rms_after_m"] <= d["holdout_rms_before_m"]  # kept findings lower the held-out error
        assert d["not_identifiable"], "TIAGo's arm_1 drive scale is absorbed: the diagnosis must say so"
        scale = {s["joint"]: s for s in d["drive_scale"]["per_joint"]}
        assert not scale["arm_1_joint"]["identifiable"]
        plausible = {(c["effect"], c["location"]): c["plausible_max"] for c in d["candidates"]}
        for f in d["findings"]:  # a size beyond what a joint has is stated as a proxy, never a confident name
            p = f["parameters"][0]
            if abs(p["value"]) - 2 * p["std"] > plausible[(f["effect"], f["location"])] and len(f["parameters"]) == 1:
                assert f["confidence"] == "low" and "proxy" in f["note"], f
                proxies.append((f["effect"], f["location"]))
    # the guide's case, so that the check above is not vacuous: arm_4's elastic lag, 24 ± 2 mrad/(N·m) where a
    # joint gives at most 10
    assert any(e == "joint_elasticity" and "arm_4" in loc for e, loc in proxies), proxies


def test_the_planned_excitation_beats_a_random_one_and_the_simulated_effects_are_named(guide):
    repo, _ = guide
    plan = json.loads((repo / "tiago-excitation.json").read_text())
    assert plan["condition_number"] < plan["condition_number_random"]
    assert (repo / "tiago-excitation-bag").is_dir()
    found = {(f["effect"], f["joint"]): f for f in
             json.loads((repo / "runs/tiago-sim/diagnose/diagnosis.json").read_text())["findings"]}
    delta = found[("time_offset", None)]["parameters"][0]["value"]
    f_s = found[("stribeck", "arm_2_joint")]["parameters"][0]["value"]
    assert 0.003 < delta < 0.0055 and 0.3 < f_s < 0.5, (delta, f_s)  # truth: 4 ms, 0.4 N·m
    assert set(found) == {("time_offset", None), ("stribeck", "arm_2_joint")}, sorted(found)  # nothing else


def test_the_bounded_benchmarks_print_their_tables(guide):
    _, outs = guide
    text = outs[-1].stdout
    assert re.search(r"^robocal\s+1\.\d{3}\s+2\.\d{3}", text, flags=re.M), text
    assert "stribeck             named in 1/1" in text, text


@pytest.mark.extended
def test_the_cross_validation_side_by_side_runs_as_printed():
    """The guide's side-by-side cross-validation command, as printed (≈ 30 s CPU; its capability — robocal
    below FIGAROH held out — is covered in CI by the split above): robocal, nested or not, below FIGAROH's own
    five-block run on every scored joint and pooled."""
    if not (REAL / "figaroh_tiago_dynamics" / "dynamic" / "tiago_effort.csv").is_file():
        pytest.skip("../shared/real-data/figaroh_tiago_dynamics is absent: the cross-validation not run")
    line = next(ln for ln in GUIDE.read_text().splitlines() if ln.startswith("PYTHONPATH=. ")
                and "--figaroh-json benchmarks/peer_figures/" in ln)
    env = {**os.environ, "PATH": os.pathsep.join([str(REPO / ".venv" / "bin"), os.environ.get("PATH", "")])}
    r = subprocess.run(["bash", "-e", "-c", line], cwd=REPO, env=env, capture_output=True, text=True, timeout=1800)
    assert r.returncode == 0, r.stderr
    rows = {m.group(1): [float(x) for x in m.group(2).split()]
            for m in re.finditer(r"^(robocal \(nested\)|robocal|FIGAROH \(run\))\s+([\d. ]+)$", r.stdout, flags=re.M)}
    nested, theirs = rows["robocal (nested)"], rows["FIGAROH (run)"]
    assert all(a < b for a, b in zip(nested, theirs)), r.stdout
