"""Bad input: one line on stderr naming file, channel and record; non-zero exit; no traceback."""

from __future__ import annotations

import json

import pytest

from conftest import run_cli
from pipeline.recording.reader import read_recording
from pipeline.recording.scene import SCENE_CHANNELS
from pipeline.recording.schemas import META_CAMPAIGN, META_FIXTURE, META_ROBOT
from pipeline.recording.writer import RecordingWriter


def assert_one_line_error(proc, *needles: str) -> None:
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr
    lines = [ln for ln in proc.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    for n in needles:
        assert n in lines[0], (n, lines[0])


def rewrite(src, dst, edit) -> None:
    """Copy a recording, passing every (topic, body) through `edit` (None drops it)."""
    rec = read_recording(src)
    with RecordingWriter(dst) as w:
        for name in (META_ROBOT, META_FIXTURE, META_CAMPAIGN):
            w.metadata(name, rec.metadata[name])
        msgs = [(t, m) for t in rec.messages if t not in SCENE_CHANNELS for m in rec.messages[t]]  # /tf: not copied
        msgs.sort(key=lambda tm: tm[1]["timestamp_ns"])
        counters: dict[str, int] = {}
        for topic, body in msgs:
            i = counters.get(topic, 0)
            counters[topic] = i + 1
            out = edit(topic, i, body)
            if out is not None:
                w.write(topic, out)


def test_not_an_mcap_file(tmp_path):
    bad = tmp_path / "notes.mcap"
    bad.write_text("this is not a recording\n")
    assert_one_line_error(run_cli("calibrate", bad, "--out", tmp_path / "o"), str(bad), "not an MCAP file")


def test_missing_file(tmp_path):
    assert_one_line_error(run_cli("calibrate", tmp_path / "nope.mcap", "--out", tmp_path / "o"), "no such file")


def test_missing_contact_channel(arc_default, tmp_path):
    dst = tmp_path / "no_contacts.mcap"
    rewrite(arc_default[0], dst, lambda t, i, m: None if t == "/touch/contact" else m)
    assert_one_line_error(run_cli("calibrate", dst, "--out", tmp_path / "o"), str(dst), "/touch/contact")


def test_nan_in_a_contact_names_the_record(arc_default, tmp_path):
    dst = tmp_path / "nan.mcap"

    def edit(topic, i, m):
        if topic == "/touch/contact" and i == 17:
            m = dict(m, joint_positions=[float("nan")] + m["joint_positions"][1:])
        return m

    # the writer refuses NaN (it is not JSON); a damaged device could still send it, so write raw text
    rec = read_recording(arc_default[0])
    with RecordingWriter(dst) as w:
        for name in (META_ROBOT, META_FIXTURE, META_CAMPAIGN):
            w.metadata(name, rec.metadata[name])
        cid = w.channel("/touch/contact")
        w.channel("/robot/joint_state")
        for i, m in enumerate(rec.messages["/touch/contact"]):
            m = edit("/touch/contact", i, m)
            w._w.add_message(cid, log_time=m["timestamp_ns"], publish_time=m["timestamp_ns"],
                             data=json.dumps(m).encode())  # json.dumps writes NaN literally
        for m in rec.messages["/robot/joint_state"]:
            w.write("/robot/joint_state", m)
    assert_one_line_error(run_cli("calibrate", dst, "--out", tmp_path / "o"),
                          str(dst), "channel /touch/contact", "record 17", "NaN")


def test_bad_axis_names_the_record(arc_default, tmp_path):
    dst = tmp_path / "axis.mcap"
    rewrite(arc_default[0], dst, lambda t, i, m: dict(m, axis="w") if t == "/touch/contact" and i == 5 else m)
    assert_one_line_error(run_cli("calibrate", dst, "--out", tmp_path / "o"), "record 5", "axis")


@pytest.mark.parametrize("fraction", [0.6])
def test_truncated_file_warns_and_calibrates_from_complete_records(arc_default, tmp_path, fraction):
    src = arc_default[0]
    data = src.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * fraction)])
    out = tmp_path / "o"
    proc = run_cli("calibrate", cut, "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert "warning" in proc.stderr and "truncated" in proc.stderr and "Traceback" not in proc.stderr
    res = json.loads((out / "results.json").read_text())
    assert 30 <= res["n_measurements"] < 100
    assert res["warnings"] and res["rms_after_m"] < 1e-4
    # every contact that was complete in the cut file is used
    full = read_recording(src).messages["/touch/contact"]
    kept = read_recording(cut).messages["/touch/contact"]
    assert kept == full[: len(kept)] and len(kept) == res["n_measurements"]
