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


def test_empty_files_are_replaced_and_own_recordings_only_with_force(tmp_path):
    """An empty file is no data: replaced.  robocal's own recording is data: refused without --force
    (left byte for byte), kept as NAME.bak with it, and a second --force never overwrites that .bak."""
    robot = tmp_path / "r6.urdf"
    robot.write_text(URDF)
    out = tmp_path / "rec.mcap"
    out.write_bytes(b"")
    sim = ("simulate", "urdf", "--urdf", robot, "--root", "b", "--tip", "l6", "--out", out)
    r = run_cli(*sim)
    assert r.returncode == 0, r.stderr
    assert written_by_robocal(out)
    first = out.read_bytes()
    r = run_cli(*sim, "--seed", "1")
    assert r.returncode == 2 and "--force" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert out.read_bytes() == first
    r = run_cli(*sim, "--seed", "1", "--force")
    assert r.returncode == 0, r.stderr
    bak = tmp_path / "rec.mcap.bak"
    assert bak.read_bytes() == first and out.read_bytes() != first
    second = out.read_bytes()
    r = run_cli(*sim, "--seed", "2", "--force")
    assert r.returncode == 2 and "rec.mcap.bak" in r.stderr and "exists already" in r.stderr, r.stderr
    assert bak.read_bytes() == first and out.read_bytes() == second
    up = tmp_path / "up.mcap"
    up.write_text("a text file")
    r = run_cli("simulate", "arc-welder", "--out", up, "--force")
    assert r.returncode != 0 and up.read_text() == "a text file"  # --force never touches someone else's file


def test_plan_and_compensate_never_overwrite_a_foreign_json_or_csv(tmp_path):
    """`robocal plan … --out` and `robocal compensate … --out`: someone else's file (a JSON with other
    keys, a CSV with other columns, a campaign-looking file without robocal's mark) is left byte for byte."""
    robot = tmp_path / "r6.urdf"
    robot.write_text(URDF)
    targets = tmp_path / "targets.csv"
    targets.write_text("x,y,z\n0.5,0.0,0.3\n")
    foreign = {"plan.json": '{"measurements": [], "note": "mine"}\n', "program.csv": "row,name,status\n1,a,ok\n",
               "old.json": '{"system": "urdf", "kind": "campaign"}\n'}
    for name, text in foreign.items():
        f = tmp_path / name
        f.write_text(text)
        before = f.read_bytes()
        if name.endswith(".csv"):
            args = ("compensate", tmp_path, "--targets", targets, "--out", f)
        else:
            args = ("plan", "urdf", "--urdf", robot, "--root", "b", "--tip", "l6", "--candidates", "50", "--select", "10",
                    "--out", f)
        r = run_cli(*args)
        assert r.returncode != 0, (name, r.stdout)
        assert "was not written by robocal" in r.stderr and "Traceback" not in r.stderr, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and name in r.stderr
        assert f.read_bytes() == before


def test_own_plans_and_programs_are_recognised_and_replaced(tmp_path):
    import numpy as np

    from pipeline.compensate import program as pg
    from pipeline.compensate.serial import Compensated

    robot = tmp_path / "r6.urdf"
    robot.write_text(URDF)
    out = tmp_path / "plan.json"
    for seed in ("0", "1"):  # a new file, then robocal's own plan (another selection) over it
        r = run_cli("plan", "urdf", "--urdf", robot, "--root", "b", "--tip", "l6", "--candidates", "50", "--select", "10",
                    "--seed", seed, "--out", out)
        assert r.returncode == 0, r.stderr
        assert written_by_robocal(out) and out.read_text().lstrip("{ \n").startswith('"generator": "robocal/')
    # robocal's program CSV (the writer `robocal compensate` uses) carries its own header
    n = 3
    c = Compensated(q=np.zeros((n, 2)), q_nominal=np.zeros((n, 2)), p_corrected=np.zeros((n, 3)),
                    R_corrected=np.repeat(np.eye(3)[None], n, 0), status=np.array(["ok"] * n),
                    correction_m=np.zeros(n), sigma_min_m=np.ones(n), error_m=np.zeros(n))
    prog = tmp_path / "program.csv"
    pg.write_program(prog, c, {"names": ["a", "b", "c"], "R": None}, ["j1", "j2"], np.zeros(n))
    assert written_by_robocal(prog)
    other = tmp_path / "other.csv"
    other.write_text(prog.read_text().replace("model_error_m", "my_column"))
    assert not written_by_robocal(other)


def test_fleet_page_and_flags_never_overwrite_a_foreign_file(tmp_path):
    """`robocal fleet --out P.html` refuses a foreign P.html or P.json before reading anything; the
    pages robocal renders carry its generator mark (so a re-run may replace them)."""
    from pipeline.fleet.html import counts, render

    for name in ("fleet.html", "fleet.json"):
        foreign = tmp_path / name
        foreign.write_text("<!DOCTYPE html><html><head><title>my notes</title></head></html>\n")
        r = run_cli("fleet", tmp_path / "no-results", "--out", tmp_path / "fleet.html")
        assert r.returncode != 0 and "was not written by robocal" in r.stderr and str(foreign) in r.stderr, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
        assert "my notes" in foreign.read_text()
        foreign.unlink()
    page, flags = tmp_path / "fleet.html", tmp_path / "fleet.json"
    page.write_text(render([], "archive", 2.5e-4, 0.01))
    import json

    flags.write_text(json.dumps(counts([])))
    assert written_by_robocal(page) and written_by_robocal(flags)
