"""The dynamics guide's section "Another robot: the Staubli TX40", run as printed on figaroh-examples' real TX40
log (the folder $ROBOCAL_TX40 names; skipped, saying so, where it is not set): the import with the drive-reading
options, `robocal run`, `robocal evaluate` below FIGAROH 1.0.2's held-out figures on every joint and pooled
(benchmarks/peer_figures/figaroh_tx40_dynamics.json), the coupled motor's terms in dynamics.yaml, and the side by
side benchmark.  Extended: the capability's CI tests are tests/test_dynamics_drive_readings.py (motor-side angles, a
coupled wrist, --rate, a coupled motor's friction recovered from the independent generator)."""

import json
import os
import re
import subprocess
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
GUIDE = REPO / "docs" / "guide" / "dynamics.md"
PEER = REPO / "benchmarks" / "peer_figures" / "figaroh_tx40_dynamics.json"
pytestmark = [pytest.mark.extended, pytest.mark.timeout(1800)]


def tx40_blocks() -> list[str]:
    return [b for b in re.findall(r"^```sh\n(.*?)^```", GUIDE.read_text(), flags=re.S | re.M) if "ROBOCAL_TX40" in b]


def test_the_tx40_section_runs_as_printed_and_beats_figaroh(tmp_path):
    folder = os.environ.get("ROBOCAL_TX40")
    if not folder or not (Path(folder) / "data" / "curr_data.csv").is_file():
        pytest.skip("$ROBOCAL_TX40 does not name figaroh-examples' examples/staubli_TX40 folder: the guide's TX40 "
                    "commands not run")
    blocks = tx40_blocks()
    assert len(blocks) == 2 and all("/work/" not in b and "/tmp/" not in b for b in blocks)
    repo = tmp_path / "repo"
    repo.mkdir()
    for name in (".venv", "benchmarks", "pipeline", "schemas", "docs"):
        (repo / name).symlink_to(REPO / name)
    env = {k: v for k, v in os.environ.items() if k != "VIRTUAL_ENV"}
    env["PATH"] = os.pathsep.join([str(REPO / ".venv" / "bin"), env.get("PATH", "")])
    outs = []
    for body in blocks:
        r = subprocess.run(["bash", "-e", "-o", "pipefail", "-c", body], cwd=repo, env=env, capture_output=True,
                           text=True, timeout=1800)
        assert r.returncode == 0 and "Traceback" not in r.stderr, f"{body}\n{r.stdout}\n{r.stderr}"
        outs.append(r)
    theirs = json.loads(PEER.read_text())["forward"]
    ev = json.loads((repo / "runs/tx40-dyn-eval/evaluation.json").read_text())["recordings"][0]
    for j, v in theirs["per_joint"].items():
        assert ev["rms_joint_Nm"][j] < v, (j, ev["rms_joint_Nm"][j], v)
    assert ev["rms_pooled_Nm"] < theirs["pooled"]
    side = yaml.safe_load((repo / "runs/tx40-dyn/identify/dynamics.yaml").read_text())["joints"]["joint_6.motor"]
    assert abs(side["fv"]["value"] - 0.616) < 0.1 and abs(side["Ia"]["value"] - 0.00964) < 0.002, side  # FIGAROH's priors
    fit = json.loads((repo / "runs/tx40-dyn/identify/fit.json").read_text())
    assert fit["decimation"] == 10 and all(fit["consistent"]["bodies_consistent"])
    rows: dict[str, list] = {"robocal": [], "FIGAROH 1.0.2 (run)": []}
    for m in re.finditer(r"^(robocal|FIGAROH 1\.0\.2 \(run\))\s+([\d. ]+)$", outs[1].stdout, flags=re.M):
        rows[m.group(1)].append([float(x) for x in m.group(2).split()])
    assert len(rows["FIGAROH 1.0.2 (run)"]) == 2, outs[1].stdout  # the forward and backward splits
    for ours, peer in zip(rows["robocal"], rows["FIGAROH 1.0.2 (run)"]):
        assert all(a < b for a, b in zip(ours, peer)), outs[1].stdout
