"""Session fixtures: simulated arc-welder recordings (simulated once per test session)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROBOCAL = str(Path(sys.executable).parent / "robocal")


def run_cli(*args: str, check: bool = False, env: dict | None = None) -> subprocess.CompletedProcess:
    """Run the installed `robocal` console script; capture text output (`env`: variables added to ours)."""
    import os

    return subprocess.run([ROBOCAL, *map(str, args)], capture_output=True, text=True, check=check, timeout=600,
                          env=None if env is None else {**os.environ, **env})


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


TIAGO_SESSIONS = ("2021-11-30", "2021-11-26", "2021-11-30-1403", "2021-11-30-1504")


@pytest.fixture(scope="session")
def tiago_frozen_protocol(tmp_path_factory):
    """FIGAROH's frozen TIAGo protocol, run once for every test that checks it: the four real mocap sessions
    imported (`robocal import csv`), `robocal calibrate` (default options) on the first, `robocal evaluate`
    of that calibration on the other three without refitting.  Returns (recordings, calibrate's finished
    process, its run folder, evaluate's finished process, its output folder); each test asserts its own
    figures on these files.  The tests that use it skip before asking for it where the data are absent."""
    from real_data import REAL as real
    d, urdf = real / "figaroh_tiago_sessions", real / "figaroh_tiago_mocap" / "tiago_48_schunk.urdf"
    tmp = tmp_path_factory.mktemp("tiago_protocol")
    recs = []
    for s in TIAGO_SESSIONS:
        out = tmp / f"{s}.mcap"
        proc = run_cli("import", "csv", d / f"qualisys_{s}_static_postures.csv", "--urdf", urdf, "--root",
                       "base_footprint", "--tip", "wrist_ft_tool_link", "--measure", "point", "--position-cols",
                       "x1,y1,z1", "--out", out)
        assert proc.returncode == 0, proc.stderr
        recs.append(out)
    cal = run_cli("calibrate", recs[0], "--out", tmp / "cal")
    assert cal.returncode == 0, cal.stderr
    ev = run_cli("evaluate", tmp / "cal", *recs[1:], "--out", tmp / "ev")
    assert ev.returncode == 0, ev.stderr
    return recs, cal, tmp / "cal", ev, tmp / "ev"


# the suite on the machine's cores, and what each test file costs: tests/ci_time.py (its hooks, by its __all__)
from ci_time import *  # noqa: E402,F401,F403
