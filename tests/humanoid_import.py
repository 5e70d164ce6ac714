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
