"""A recording is data, not a cache: no command replaces an existing recording — even one robocal
wrote, of another robot (a copy of recordings/delta-tracker.mcap, the case fuzzing found) — without
--force.  Refused in one line before any work, the file byte for byte; --force keeps the old one as
NAME.bak and never overwrites a .bak; a recording of real measurements is never replaced (the
acquisition itself: tests/test_output_guard_acquire.py)."""

from __future__ import annotations

import shutil

import pytest

from conftest import run_cli
from fuzz_door import MARKER_ARGS, robot
from hostile_support import BUNDLED

DELTA = BUNDLED["delta-tracker"]


@pytest.fixture(scope="module")
def pr6(tmp_path_factory):
    """(URDF, CSV, a recording imported from it) of a small robot (tests/fuzz_door.py)."""
    return robot(tmp_path_factory.mktemp("pr6"))


def _commands(d, u, csv, rec, out):
    imp = ("--urdf", u, "--root", "base", "--tip", "flange")
    return {
        "import csv": ("import", "csv", csv, *imp, "--measure", "point", *MARKER_ARGS, "--out", out),
        "import ros2": ("import", "ros2", d / "bag", *imp, "--out", out),
        "import images": ("import", "images", d, "--target", "chessboard:9x6:0.02", "--joints", csv, *imp, "--out", out),
        "simulate urdf": ("simulate", "urdf", *imp, "--out", out),
        "simulate arc-welder": ("simulate", "arc-welder", "--out", out),
        "simulate delta-tracker": ("simulate", "delta-tracker", "--out", out),
        "simulate scorbot-scanner": ("simulate", "scorbot-scanner", "--out", out),
        "recover": ("recover", rec, out),
        "acquire": ("acquire", "--device", f"bridge={d / 'no-port'}", "--out", out),
    }


@pytest.mark.parametrize("command", ["import csv", "import ros2", "import images", "simulate urdf",
                                     "simulate arc-welder", "simulate delta-tracker", "simulate scorbot-scanner",
                                     "recover", "acquire"])
def test_no_command_replaces_an_existing_recording_without_force(pr6, tmp_path, command):
    u, csv, rec = pr6
    out = tmp_path / "my.mcap"
    shutil.copy(DELTA, out)
    r = run_cli(*_commands(tmp_path, u, csv, rec, out)[command])
    assert r.returncode == 2 and "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert f"{out}: holds a recording already" in r.stderr
    assert ("--force" in r.stderr) == (command != "acquire")  # acquire has no --force: it never replaces one
    assert out.read_bytes() == DELTA.read_bytes() and not (tmp_path / "my.mcap.bak").exists()


def test_simulate_fleet_never_replaces_an_archived_campaign(tmp_path):
    from pipeline.fleet.simulate import FleetSpec, campaign_path

    arch = tmp_path / "archive"
    first = campaign_path(arch, FleetSpec(robots=1, months=1), 0, 1)
    first.parent.mkdir(parents=True)
    shutil.copy(DELTA, first)
    r = run_cli("simulate", "fleet", "--robots", "1", "--months", "1", "--contacts", "10", "--out", arch)
    assert r.returncode == 2 and "holds a recording already" in r.stderr and str(first) in r.stderr, r.stderr
    assert first.read_bytes() == DELTA.read_bytes() and not (arch / "fleet.truth.json").exists()


@pytest.mark.parametrize("command", ["import csv", "recover"])
def test_force_keeps_the_old_recording_and_never_overwrites_a_backup(pr6, tmp_path, command):
    u, csv, rec = pr6
    out, bak = tmp_path / "my.mcap", tmp_path / "my.mcap.bak"
    shutil.copy(DELTA, out)
    args = _commands(tmp_path, u, csv, rec, out)[command]
    r = run_cli(*args, "--force")
    assert r.returncode == 0, r.stderr
    assert bak.read_bytes() == DELTA.read_bytes() and out.read_bytes() != DELTA.read_bytes()
    new = out.read_bytes()
    r = run_cli(*args, "--force")
    assert r.returncode == 2 and f"{bak}, which exists already" in r.stderr, r.stderr
    assert bak.read_bytes() == DELTA.read_bytes() and out.read_bytes() == new


def test_a_recording_cut_short_is_never_replaced(pr6, tmp_path):
    """No footer: an acquisition that crashed (`robocal recover` reads it) — not even with --force."""
    u, csv, rec = pr6
    out = tmp_path / "my.mcap"
    cut = BUNDLED["arc-welder-touch"].read_bytes()[:60_000]
    out.write_bytes(cut)
    r = run_cli(*_commands(tmp_path, u, csv, rec, out)["import csv"], "--force")
    assert r.returncode == 2 and "cut short" in r.stderr and "even with --force" in r.stderr, r.stderr
    assert out.read_bytes() == cut and not (tmp_path / "my.mcap.bak").exists()
