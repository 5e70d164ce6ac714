"""Session fixtures: simulated arc-welder recordings (simulated once per test session)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROBOCAL = str(Path(sys.executable).parent / "robocal")


def run_cli(*args: str, check: bool = False) -> subprocess.CompletedProcess:
    """Run the installed `robocal` console script; capture text output."""
    return subprocess.run([ROBOCAL, *map(str, args)], capture_output=True, text=True, check=check, timeout=600)


def _simulate(tmp: Path, name: str, *args: str) -> tuple[Path, dict]:
    rec, truth = tmp / f"{name}.mcap", tmp / f"{name}.truth.json"
    run_cli("simulate", "arc-welder", "--out", rec, "--truth", truth, *args, check=True)
    return rec, json.loads(truth.read_text())


@pytest.fixture(scope="session")
def arc_default(tmp_path_factory) -> tuple[Path, dict]:
    """Default truth, default noise, 100 contacts."""
    return _simulate(tmp_path_factory.mktemp("arc"), "default", "--seed", "3")


@pytest.fixture(scope="session")
def arc_noise_free(tmp_path_factory) -> tuple[Path, dict]:
    return _simulate(tmp_path_factory.mktemp("arc"), "clean", "--seed", "4", "--noise-scale", "0")
