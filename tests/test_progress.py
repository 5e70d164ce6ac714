"""Progress of long stages in a log (not a terminal): periodic full lines with counts, nothing for a
short job; on a terminal one line redrawn; `robocal reprocess`'s counts in a non-terminal log."""

from __future__ import annotations

import io
import shutil
from pathlib import Path

from conftest import run_cli
from pipeline.progress import Ticker

REPO = Path(__file__).resolve().parents[1]


def test_log_lines_only_when_the_job_is_long(monkeypatch):
    clock = [0.0]
    monkeypatch.setattr("pipeline.progress.time.monotonic", lambda: clock[0])
    quick = io.StringIO()
    t = Ticker("report", total=4, unit="parts", stream=quick, every_s=10)
    for _ in range(4):
        clock[0] += 1
        t("x")
    t.done()
    assert quick.getvalue() == ""  # 4 s: silent
    slow = io.StringIO()
    clock[0] = 0.0
    t = Ticker("simulate fleet", total=6, unit="campaigns", stream=slow, every_s=10)
    for i in range(6):
        clock[0] += 7
        t(f"r{i}")
    t.done()
    lines = slow.getvalue().splitlines()
    assert lines[0].startswith("simulate fleet: 2/6 campaigns — r1, 14 s, ETA 28 s")
    assert lines[-1] == "simulate fleet: 6/6 campaigns — done, 42 s" and "\r" not in slow.getvalue()
    assert len(lines) == 4  # at 14, 28 and 42 s, and the final line


def test_terminal_redraws_one_line():
    tty = io.StringIO()
    t = Ticker("report", total=2, stream=tty, tty=True)
    t("a")
    t("b")
    t.done()
    out = tty.getvalue()
    assert out.count("\r\033[K") == 3 and out.endswith("report: 2/2 — done, 0 s\n")


def test_steps_reach_the_ticker_and_its_log_only_off_a_terminal(tmp_path, monkeypatch):
    """`step` inside `reporting` reaches the ticker (nothing outside it); off a terminal the lines also go to the
    log file, on a terminal only to the redrawn line; ROBOCAL_PROGRESS_EVERY_S sets the interval."""
    from pipeline.progress import reporting, step

    monkeypatch.setenv("ROBOCAL_PROGRESS_EVERY_S", "0")
    step("nobody listens")  # no reporter: nothing happens
    for tty in (False, True):
        out, log = io.StringIO(), tmp_path / f"progress{tty}.log"
        t = Ticker("diagnose", stream=out, tty=tty, log=log, count=False)
        assert t.every_s == 0
        with reporting(t):
            for j in range(3):
                step(f"signatures: joint {j + 1} of 3")
        step("after the block")
        t.done()
        if tty:
            assert not log.exists() and out.getvalue().count("\r\033[K") == 4
        else:
            lines = log.read_text().splitlines()
            assert [ln.split(",")[0] for ln in lines] == [f"diagnose: signatures: joint {j} of 3" for j in (1, 2, 3)] + [
                "diagnose: done"]
            assert out.getvalue().splitlines() == lines and "after the block" not in out.getvalue()


def test_reprocess_reports_counts_in_a_log(tmp_path):
    arch = tmp_path / "archive"
    arch.mkdir()
    for name in ("arc-welder-touch",):
        shutil.copy(REPO / "recordings" / f"{name}.mcap", arch)
        shutil.copy(REPO / "recordings" / f"{name}.expected.json", arch)
    p = run_cli("reprocess", arch, "--out", tmp_path / "out", "--engine", "serial")
    assert p.returncode == 0, p.stderr
    assert "reprocess: 1 recording(s) to process, 0 done before" in p.stderr
    assert "reprocess: 1/1 recordings — 1 ok, 0 failed, 0 regressed" in p.stderr
