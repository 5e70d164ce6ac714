"""Bad drive-state input is a clear error and loses nothing: a non-finite drive value rejects its
frame (one NaN would make the whole encoder stream unreadable), a NaN compliance or averaging window
is refused in one line, and a refused acquisition output leaves the process as it was."""

from __future__ import annotations

import signal

import numpy as np
import pytest

from pipeline.acquire.protocol import decode_samples_drive, encode_samples_drive
from pipeline.acquire.run import acquire
from pipeline.errors import RobocalError
from pipeline.ingest.drive import DEFAULT_WINDOW_S, window_of
from pipeline.simulate.urdf_drive import parse_compliance


def test_a_drive_frame_with_nan_is_rejected_and_a_finite_one_decodes():
    t, q = np.arange(3, dtype=np.int64), np.zeros((3, 2))
    ok = {"effort": np.ones((3, 2))}
    t2, q2, d2 = decode_samples_drive(encode_samples_drive(t, q, ok))
    assert np.array_equal(t2, t) and np.array_equal(d2["effort"], ok["effort"])
    bad = {"effort": np.array([[1.0, np.nan], [1.0, 1.0], [1.0, 1.0]])}
    with pytest.raises(ValueError, match="NaN or inf"):
        decode_samples_drive(encode_samples_drive(t, q, bad))


@pytest.mark.parametrize("text", ["j2=nan", "j2=inf", "j2=-1e-6"])
def test_a_compliance_must_be_finite_and_non_negative(text):
    with pytest.raises(ValueError, match="finite value ≥ 0"):
        parse_compliance(text, ["j1", "j2"])


@pytest.mark.parametrize("meta", [{"ros2": {"pairing": {"window_s": "abc"}}}, {"ros2": {"pairing": {"window_s": float("nan")}}},
                                  {"ros2": {"pairing": {"window_s": 0}}}])
def test_a_bad_averaging_window_is_one_line(meta):
    with pytest.raises(RobocalError, match="window_s"):
        window_of(meta, "r.mcap")
    assert window_of({"ros2": "not a dict"}, "r.mcap") == DEFAULT_WINDOW_S
    assert window_of({"ros2": {"pairing": {"window_s": 0.3}}}, "r.mcap") == 0.3


def test_a_refused_acquisition_output_changes_nothing(tmp_path):
    foreign = tmp_path / "notes" / "mine.txt"
    foreign.parent.mkdir()
    foreign.write_text("my notes")
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    with pytest.raises(RobocalError, match="was not written by robocal"):
        acquire({"bridge": "/dev/null"}, foreign)
    assert {s: signal.getsignal(s) for s in before} == before and foreign.read_text() == "my notes"
