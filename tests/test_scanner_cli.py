"""Scanner recordings end to end: simulate → MCAP → calibrate (CLI), and bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pipeline.recording.reader import read_recording
from pipeline.recording.schemas import META_CAMPAIGN, META_ROBOT, validator
from pipeline.recording.writer import write_campaign
from pipeline.systems import scorbot_scanner as sc

ROBOCAL = [sys.executable, "-c", "from pipeline.cli import main; main()"]


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*ROBOCAL, *args], capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("scan")
    r = run("simulate", "scorbot-scanner", "--out", str(d / "rec.mcap"), "--truth", str(d / "TRUTH.json"))
    assert r.returncode == 0, r.stderr
    return d / "rec.mcap", d / "TRUTH.json"


def test_recording_has_schema_valid_messages_and_no_truth(recording):
    rec = read_recording(recording[0])
    msgs = rec.require(sc.MEASUREMENT_CHANNEL)
    assert len(msgs) == 5 and all(len(m["corner_px"]) == 5 for m in msgs)
    for m in msgs:
        validator("scanner_stripe").validate(m)
    assert rec.metadata[META_CAMPAIGN]["system"] == sc.SYSTEM
    assert "truth" not in json.dumps(rec.metadata).lower()
    truth = json.loads(recording[1].read_text())
    assert np.isclose(truth["scanner"]["f"], 7.25e-3)
    model, table = sc.load(rec)
    assert table["pixel"].shape == (25, 2) and table["corner"].shape == (25, 3)


def test_cli_calibrate_scanner(recording, tmp_path):
    r = run("calibrate", str(recording[0]), "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "results.json").read_text())
    assert doc["system"] == sc.SYSTEM and doc["solver"] == "lm"
    assert doc["rms_after_m"] < 2e-4 and doc["scanner"]["rms_at_nominal_m"] > 0.1
    reasons = {p["name"]: p.get("reason", "") for p in doc["parameters"] if not p["identifiable"]}
    assert set(reasons) == {"scanner.f", "scanner.v0", "scanner.theta"}
    model = json.loads((tmp_path / "model.json").read_text())
    assert model["kind"] == "scorbot_scanner" and model["gauge"]["fixed"] == "f"


def _write(path: Path, msgs: list[dict]) -> None:
    arm = sc.nominal_arm()
    t = np.array([m["timestamp_ns"] for m in msgs], np.int64)
    q = np.array([m["joint_positions"] for m in msgs])
    write_campaign(path, {META_ROBOT: arm.to_dict(), META_CAMPAIGN: {"system": sc.SYSTEM}},
                   (t, q, [j.name for j in arm.joints]), [(sc.MEASUREMENT_CHANNEL, m) for m in msgs])


def _good(recording) -> list[dict]:
    return [dict(m) for m in read_recording(recording[0]).messages[sc.MEASUREMENT_CHANNEL]]


@pytest.mark.parametrize("case,needle", [
    ("mismatch", "record 2: 5 corner pixels but 4 corner coordinates"),
    ("outside", "record 3: corner_px[1] = (700.0, 100.0) px lies outside the 640x480 image"),
    ("degenerate", "records 0, 1, 2, 3, 4: degenerate pose set"),
])
def test_bad_input_one_line_error(recording, tmp_path, case, needle):
    msgs = _good(recording)
    if case == "mismatch":
        msgs[2]["corner_m"] = msgs[2]["corner_m"][:4]
    elif case == "outside":
        msgs[3]["corner_px"] = [msgs[3]["corner_px"][0], [700.0, 100.0]] + msgs[3]["corner_px"][2:]
    else:
        for m in msgs:
            m["joint_positions"] = msgs[0]["joint_positions"]
    bad = tmp_path / f"{case}.mcap"
    _write(bad, msgs)
    r = run("calibrate", str(bad), "--out", str(tmp_path / "out"))
    assert r.returncode == 2
    line = " ".join(r.stderr.split())
    assert f"channel {sc.MEASUREMENT_CHANNEL}" in line and needle in line and str(bad.name) in line
    assert "Traceback" not in r.stderr
