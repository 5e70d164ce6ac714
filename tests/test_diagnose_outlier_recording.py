"""End to end on a real MCAP: one bad latch in the bundled arc-welder recording is named as an
outlier record by `robocal diagnose`, not diagnosed as physics; the declared repeatability is read
from the campaign metadata."""

from __future__ import annotations

import json
from pathlib import Path

from conftest import run_cli
from pipeline.recording.reader import read_recording
from pipeline.recording.writer import RecordingWriter

BUNDLED = Path(__file__).resolve().parents[1] / "recordings" / "arc-welder-touch.mcap"


def _copy_with_bad_latch(src: Path, dst: Path, record: int, dq2_rad: float, repeatability: float | None) -> None:
    rec = read_recording(src)
    with RecordingWriter(dst) as w:
        for name, value in rec.metadata.items():
            if name == "robocal.campaign" and repeatability is not None:
                value = {**value, "robot_repeatability_3sigma_m": repeatability}
            w.metadata(name, value)
        msgs = [(t, m) for t, ms in rec.messages.items() for m in ms]
        msgs.sort(key=lambda tm: tm[1]["timestamp_ns"])
        k = -1
        for topic, m in msgs:
            if topic == "/touch/contact":
                k += 1
                if k == record:  # the encoders latched a little off: J2 read 2 mrad wrong (~0.7 mm at the tip)
                    m = {**m, "joint_positions": [q + (dq2_rad if j == 1 else 0.0)
                                                  for j, q in enumerate(m["joint_positions"])]}
            w.write(topic, m)


def test_one_bad_latch_is_an_outlier_record_named_by_robocal_diagnose(tmp_path):
    rec = tmp_path / "bad-latch.mcap"
    _copy_with_bad_latch(BUNDLED, rec, 37, 2e-3, 1e-4)
    out = tmp_path / "d"
    res = run_cli("diagnose", rec, "--out", out, "--bootstrap", "10")
    assert res.returncode == 0, res.stderr
    doc = json.loads((out / "diagnosis.json").read_text())
    assert [o["record"] for o in doc["outlier_records"]] == [37]
    assert "outlier record 37" in res.stdout
    assert not any(f["confidence"] == "high" for f in doc["findings"])
    assert doc["noise_floor"] is not None and not doc["noise_floor"]["above_floor"]  # the rest is at the floor
    assert doc["holdout_rms_after_m"] <= doc["holdout_rms_before_m"]
    assert doc["status"] in ("clean", "explained")
