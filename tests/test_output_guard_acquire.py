"""The side outputs are guarded like the main ones: `acquire --summary`, `device-sim --report` and
`simulate … --truth` never overwrite a file robocal did not create (one-line error, the file left
byte for byte, nothing else written, checked before any work); robocal's own files are replaced."""

from __future__ import annotations

import json
import shutil

import pytest

from conftest import run_cli
from r6_robot import BARE_URDF as URDF
from stream_support import record_over_pty

from pipeline.recording.output import library_of, written_by_robocal

FOREIGN = {"json": b'{"stop_reason": "mine", "devices": {}}\n', "text": b"someone's notes\n"}


def _refused(r, path, before: bytes) -> None:
    assert r.returncode != 0, r.stdout
    assert "was not written by robocal" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and path.name in r.stderr, r.stderr
    assert path.read_bytes() == before


@pytest.mark.parametrize("kind", sorted(FOREIGN))
def test_a_foreign_summary_report_or_truth_is_refused_before_any_work(tmp_path, kind):
    robot = tmp_path / "r6.urdf"
    robot.write_text(URDF)
    foreign = tmp_path / "mine.json"
    foreign.write_bytes(FOREIGN[kind])
    out = tmp_path / "sub" / "rec.mcap"
    runs = {  # the device paths need not exist: the check comes before any port is opened
        "acquire --summary": ("acquire", "--device", f"bridge={tmp_path / 'no-such-port'}", "--out", out,
                              "--summary", foreign),
        "device-sim --report": ("device-sim", "arc-welder", "--report", foreign, "--link-dir", tmp_path / "sub"),
        "simulate arc-welder --truth": ("simulate", "arc-welder", "--out", out, "--truth", foreign),
        "simulate delta-tracker --truth": ("simulate", "delta-tracker", "--out", out, "--truth", foreign),
        "simulate scorbot-scanner --truth": ("simulate", "scorbot-scanner", "--out", out, "--truth", foreign),
        "simulate urdf --truth": ("simulate", "urdf", "--urdf", robot, "--root", "b", "--tip", "l6", "--out", out,
                                  "--truth", foreign),
    }
    for what, args in runs.items():
        r = run_cli(*args)
        _refused(r, foreign, FOREIGN[kind])
        assert not (tmp_path / "sub").exists(), what  # nothing written, no folder made


def test_robocal_replaces_its_own_summary_report_and_truth(tmp_path):
    """A real run over a pty pair (device-sim → acquire) with robocal-written files at every side
    output: the summary and report are replaced by this run's documents (a truth file, like its
    recording, only with --force: the old one kept as .bak)."""
    direct, truth = tmp_path / "direct.mcap", tmp_path / "truth.json"
    run_cli("simulate", "arc-welder", "--contacts", "10", "--seed", "3", "--out", direct, "--truth", truth, check=True)
    first = truth.read_bytes()
    assert written_by_robocal(truth)
    run_cli("simulate", "arc-welder", "--contacts", "12", "--seed", "3", "--out", direct, "--truth", truth, "--force",
            check=True)  # a recording and its truth are data: replaced with --force only, the old ones kept as .bak
    assert truth.read_bytes() != first and json.loads(truth.read_text())["campaign"]["contacts"] == 12
    assert (tmp_path / "truth.json.bak").read_bytes() == first and (tmp_path / "direct.mcap.bak").is_file()
    for name in ("summary.json", "sim.json"):  # robocal's own JSON (a truth file) where acquire and device-sim write
        shutil.copy(truth, tmp_path / name)
    _, s, rep = record_over_pty(tmp_path, "arc-welder", ("--recording", str(direct), "--speed", "40"))
    assert s["stop_reason"] == "campaign complete" and s["devices"]["bridge"]["samples"] > 0
    assert rep["devices"]["bridge"]["sent"] > 0
    for name in ("summary.json", "sim.json"):
        assert written_by_robocal(tmp_path / name) and "campaign" not in json.loads((tmp_path / name).read_text())
    # the acquisition is real measurements: marked in its header, never replaced — not even with --force —
    # and a recovered copy keeps the mark
    acq = tmp_path / "acq.mcap"
    assert "acquire" in library_of(acq).split()
    before = acq.read_bytes()
    r = run_cli("simulate", "arc-welder", "--contacts", "10", "--out", acq, "--force")
    assert r.returncode == 2 and "real measurements (robocal acquire)" in r.stderr and "even with --force" in r.stderr
    assert acq.read_bytes() == before and not (tmp_path / "acq.mcap.bak").exists()
    copy = tmp_path / "recovered.mcap"
    run_cli("recover", acq, copy, check=True)
    assert library_of(copy).split()[1:] == ["recover", "acquire"]
    r = run_cli("recover", acq, copy, "--force")
    assert r.returncode == 2 and "real measurements" in r.stderr, r.stderr


def test_the_same_file_for_recording_and_truth_is_refused_and_truth_into_a_new_folder_is_written(tmp_path):
    """`--out X --truth X` would replace the recording with TRUTH.json: one line, nothing written.
    A --truth path in a folder that does not exist yet is made, as --out's is (the URDF simulator
    wrote the recording, then failed with a traceback)."""
    robot = tmp_path / "r6.urdf"
    robot.write_text(URDF)
    same = tmp_path / "same.mcap"
    urdf_args = ("simulate", "urdf", "--urdf", robot, "--root", "b", "--tip", "l6")
    for args in (("simulate", "delta-tracker"), ("simulate", "scorbot-scanner"), ("simulate", "arc-welder"), urdf_args):
        r = run_cli(*args, "--out", same, "--truth", same)
        assert r.returncode == 2 and "given as both --out and --truth" in r.stderr, r.stderr
        assert "Traceback" not in r.stderr and not same.exists(), args
    truth = tmp_path / "new" / "deeper" / "TRUTH.json"
    r = run_cli(*urdf_args, "--out", tmp_path / "u.mcap", "--truth", truth)
    assert r.returncode == 0, r.stderr
    assert written_by_robocal(truth) and "parameters" in json.loads(truth.read_text())
