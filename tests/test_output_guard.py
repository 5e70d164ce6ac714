"""robocal never overwrites a file it did not create: a recording's output path that holds someone
else's file is a one-line error and the file is left byte for byte; robocal's own recordings (and
empty files) are replaced."""

from __future__ import annotations

from conftest import run_cli
from pipeline.recording.output import written_by_robocal
from test_urdf_plan import URDF


def test_foreign_file_is_never_overwritten(tmp_path):
    robot = tmp_path / "r6.urdf"
    robot.write_text(URDF)
    foreign = tmp_path / "notes.mcap"
    foreign.write_bytes(b"\x89MCAP0\r\n someone else's bytes")
    before = foreign.read_bytes()
    for args in (("simulate", "urdf", "--urdf", robot, "--root", "b", "--tip", "l6", "--out", foreign),
                 ("simulate", "scorbot-scanner", "--out", foreign)):
        r = run_cli(*args)
        assert r.returncode != 0 and "was not written by robocal" in r.stderr and "Traceback" not in r.stderr, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1
        assert foreign.read_bytes() == before


def test_own_recordings_and_empty_files_are_replaced(tmp_path):
    robot = tmp_path / "r6.urdf"
    robot.write_text(URDF)
    out = tmp_path / "rec.mcap"
    out.write_bytes(b"")
    for _ in range(2):  # an empty file, then robocal's own recording
        r = run_cli("simulate", "urdf", "--urdf", robot, "--root", "b", "--tip", "l6", "--out", out)
        assert r.returncode == 0, r.stderr
        assert written_by_robocal(out)
    up = tmp_path / "up.mcap"
    up.write_text("a text file")
    r = run_cli("simulate", "arc-welder", "--out", up)
    assert r.returncode != 0 and up.read_text() == "a text file"
