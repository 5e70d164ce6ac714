"""`robocal import csv` of the independent humanoid generator's table (tests/independent_humanoid.py): both
hands as tips, the torso's third joint driven by the other two. Shared by the physics tests."""

from __future__ import annotations

import subprocess
from pathlib import Path

from conftest import run_cli

COUPLED = ("--coupled", "torso_j3=-torso_j1-torso_j2")


def import_humanoid_run(d: Path, rec: Path, csv: str = "postures.csv") -> subprocess.CompletedProcess:
    """Import `d/csv` with `d/humanoid.urdf` into `rec`; the finished process (for bad-input tests)."""
    return run_cli("import", "csv", d / csv, "--urdf", d / "humanoid.urdf", "--root", "base",
                   "--tip", "left_hand=lx,ly,lz", "--tip", "right_hand=rx,ry,rz", *COUPLED,
                   "--measure", "point", "--out", rec)


def import_humanoid(d: Path, rec: Path, csv: str = "postures.csv") -> Path:
    """Import as `import_humanoid_run`, asserting success; the recording's path."""
    r = import_humanoid_run(d, rec, csv)
    assert r.returncode == 0, r.stderr
    return rec


def evaluate_at_noise_floor(run_dir: Path, rec: Path, out: Path, noise_m: float) -> float:
    """`robocal evaluate` of calibration `run_dir` on another session `rec` (no refit): asserts its RMS of
    the 3-D error is below 1.3 × the noise floor √3·`noise_m` (m); returns it."""
    import json

    import numpy as np

    r = run_cli("evaluate", run_dir, rec, "--out", out)
    assert r.returncode == 0, r.stderr
    (ev,) = json.loads((out / "evaluation.json").read_text())["recordings"]
    assert ev["rms_3d_m"] < 1.3 * np.sqrt(3) * noise_m, ev["rms_3d_m"]
    return ev["rms_3d_m"]


def calibrated_tree(rec: Path, physics: str, doc: dict):
    """(tree model of recording `rec` with the `physics` terms, its calibrated parameter vector from the
    run's results `doc`), the names checked to match."""
    import numpy as np

    from pipeline.recording.reader import read_recording
    from pipeline.systems.registry import detect, load_with_physics

    r = read_recording(rec)
    model, _ = load_with_physics(detect(r), r, physics, None)
    assert model.parameter_names() == [q["name"] for q in doc["parameters"]]
    return model, np.array([q["estimate"] for q in doc["parameters"]])
