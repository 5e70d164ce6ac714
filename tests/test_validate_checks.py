"""Validation catches each listed defect in a purpose-made bad recording, naming the record."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.errors import RobocalError
from pipeline.recording.writer import RecordingWriter
from pipeline.stages.runner import StageFailed, run_stage
from pipeline.validate import checks as C
from tests.pipeline_support import base_campaign, write


def validate(tmp_path: Path, meta, js, contacts, raw=None, expect_fail: bool = False,
             stream_encoding: str = "protobuf") -> dict[str, list[dict]]:
    rec = write(tmp_path / "bad.mcap", meta, js, contacts, raw, stream_encoding=stream_encoding)
    run = tmp_path / "run"
    run_stage(run, "ingest", recording=rec)
    if expect_fail:
        with pytest.raises(StageFailed):
            run_stage(run, "validate")
    else:
        run_stage(run, "validate")
    doc = json.loads((run / "validate" / "validate.json").read_text())
    out: dict[str, list[dict]] = {}
    for c in doc["checks"]:
        out.setdefault(c["name"], []).append(c)
    return out


def test_an_outlier_fit_stopped_by_its_evaluation_cap_is_a_warning(tmp_path):
    """The outlier screen's first robust fit is capped (validate's outlier_fit_max_nfev); a fit that stops at
    the cap says so (warn), one that converges adds nothing."""
    rec = write(tmp_path / "c.mcap", *base_campaign())
    run_stage(tmp_path / "run", "ingest", recording=rec)
    run_stage(tmp_path / "run", "validate", {"outlier_fit_max_nfev": 2})
    doc = json.loads((tmp_path / "run" / "validate" / "validate.json").read_text())
    (w,) = [c for c in doc["checks"] if c["name"] == "outlier_fit"]
    assert w["status"] == "warn" and "stopped at its 2-evaluation cap" in w["message"] and doc["status"] == "warn"
    assert w["message"].startswith(str(rec))
    (tmp_path / "full").mkdir()
    checks = validate(tmp_path / "full", *base_campaign())
    assert "outlier_fit" not in checks


def status_of(checks: dict, name: str, channel: str) -> dict:
    (c,) = [c for c in checks[name] if c["channel"] == channel]
    return c


def test_clean_recording_passes_every_check(tmp_path):
    checks = validate(tmp_path, *base_campaign())
    bad = [c for cs in checks.values() for c in cs if c["status"] != "pass"]
    assert bad == []
    assert {"schema", "finite", "time_monotonic", "time_gaps", "duplicates", "joint_limits", "face_coordinate",
            "outliers"} <= set(checks)


def test_schema_violation_fails_naming_the_record(tmp_path):
    meta, js, contacts = base_campaign()
    del contacts[7]["face"]
    contacts[12]["axis"] = "w"
    checks = validate(tmp_path, meta, js, contacts, expect_fail=True)
    c = status_of(checks, "schema", "/touch/contact")
    assert c["status"] == "fail" and c["records"] == [7, 12]
    assert "record 7" in c["message"] and "face" in c["message"]


def test_schema_checks_every_sample_of_a_long_array(tmp_path):
    """Archived JSON stream: one string deep inside a 250×6 batch."""
    meta, js, contacts = base_campaign()
    js[3]["positions"][200][2] = "oops"
    checks = validate(tmp_path, meta, js, contacts, expect_fail=True, stream_encoding="json")
    c = status_of(checks, "schema", "/robot/joint_state")
    assert c["status"] == "fail" and c["records"] == [3]


def test_protobuf_stream_messages_that_break_the_schema_are_all_named(tmp_path):
    """Protobuf stream: NaN deep inside batch 3, too few positions in batch 8 — both named, one fail;
    the stream's times from the other batches and every other channel still checked."""
    meta, js, contacts = base_campaign()
    js[3]["positions"][200][2] = float("nan")
    js[8]["positions"] = js[8]["positions"][:-1]
    from pipeline.recording import joint_state_batch as JSB

    rec = tmp_path / "pb.mcap"
    with RecordingWriter(rec) as w:  # write the damaged batches as raw protobuf (the encoder refuses them)
        for k, v in meta.items():
            w.metadata(k, v)
        items = [(m["timestamp_ns"], 0, i, m) for i, m in enumerate(js)] + [(m["timestamp_ns"], 1, i, m)
                                                                            for i, m in enumerate(contacts)]
        for t, kind, i, m in sorted(items, key=lambda x: x[0]):
            if kind == 1:
                w.write("/touch/contact", m)
                continue
            body = JSB.JointStateBatch(timestamp_ns=m["timestamp_ns"], joint_names=m["joint_names"],
                                       sample_offsets_ns=[x - m["timestamp_ns"] for x in m["timestamps_ns"]],
                                       positions=[v for row in m["positions"] for v in row]).SerializeToString()
            w._add("/robot/joint_state", w.channel("/robot/joint_state"), t, t, body)
    run = tmp_path / "run"
    run_stage(run, "ingest", recording=rec)
    with pytest.raises(StageFailed):
        run_stage(run, "validate")
    checks = json.loads((run / "validate" / "validate.json").read_text())["checks"]
    (c,) = [c for c in checks if c["name"] == "schema" and c["channel"] == "/robot/joint_state"]
    assert c["status"] == "fail" and c["records"] == [3, 8] and str(rec) in c["message"]
    assert "record 3: positions hold NaN or inf" in c["message"] and "\n" not in c["message"]
    assert any(c["name"] == "time_monotonic" and c["status"] == "pass" for c in checks)
    assert any(c["name"] == "duplicates" and c["channel"] == "/robot/joint_state" for c in checks)
    assert any(c["channel"] == "/touch/contact" and c["name"] == "schema" and c["status"] == "pass" for c in checks)


def test_non_monotonic_encoder_time_fails(tmp_path):
    meta, js, contacts = base_campaign()
    t = js[5]["timestamps_ns"]
    t[10], t[11] = t[11], t[10]
    checks = validate(tmp_path, meta, js, contacts, expect_fail=True)
    c = status_of(checks, "time_monotonic", "/robot/joint_state")
    assert c["status"] == "fail" and c["records"] == [5]


def test_gap_in_encoder_stream_warns(tmp_path):
    meta, js, contacts = base_campaign()
    del js[9]  # a whole second of samples lost
    checks = validate(tmp_path, meta, js, contacts)
    c = status_of(checks, "time_gaps", "/robot/joint_state")
    assert c["status"] == "warn" and c["records"] == [9]  # the message after the gap (indices shift)


def test_duplicated_contact_warns(tmp_path):
    meta, js, contacts = base_campaign()
    contacts.insert(21, dict(contacts[20]))
    checks = validate(tmp_path, meta, js, contacts)
    c = status_of(checks, "duplicates", "/touch/contact")
    assert c["status"] == "warn" and c["records"] == [21]


def test_nan_fails_naming_the_record(tmp_path):
    meta, js, contacts = base_campaign()
    body = json.dumps({**contacts[4], "joint_positions": [float("nan")] + contacts[4]["joint_positions"][1:]})
    assert "NaN" in body
    checks = validate(tmp_path, meta, js, contacts, raw={4: body.encode()}, expect_fail=True)
    c = status_of(checks, "finite", "/touch/contact")
    assert c["status"] == "fail" and c["records"] == [4]


def test_joint_outside_limits_fails(tmp_path):
    meta, js, contacts = base_campaign()
    contacts[9]["joint_positions"][4] = math.radians(140)  # J5 limit ±135°
    checks = validate(tmp_path, meta, js, contacts, expect_fail=True)
    c = status_of(checks, "joint_limits", "/touch/contact")
    assert c["status"] == "fail" and c["records"] == [9] and "J5" in c["message"]


def test_contact_not_matching_its_face_fails(tmp_path):
    meta, js, contacts = base_campaign()
    contacts[3]["coordinate"] += 0.02
    other = "x" if contacts[6]["axis"] != "x" else "y"
    contacts[6]["axis"] = other
    checks = validate(tmp_path, meta, js, contacts, expect_fail=True)
    c = status_of(checks, "face_coordinate", "/touch/contact")
    assert c["status"] == "fail" and c["records"] == [3, 6]


def test_gross_outlier_is_flagged_after_a_first_fit(tmp_path):
    meta, js, contacts = base_campaign()
    contacts[17]["joint_positions"][1] += 0.01  # ~4 mm off at the tip; joints still in limits
    checks = validate(tmp_path, meta, js, contacts)
    c = status_of(checks, "outliers", "/touch/contact")
    assert c["status"] == "warn" and c["records"] == [17]


def test_a_failed_validation_stops_the_run_with_the_reason(tmp_path):
    from tests.conftest import run_cli

    meta, js, contacts = base_campaign()
    contacts[9]["joint_positions"][4] = math.radians(140)
    rec = write(tmp_path / "bad.mcap", meta, js, contacts)
    p = run_cli("run", rec, "--out", tmp_path / "run")
    assert p.returncode == 2
    assert "joint_limits" in p.stderr and "record" in p.stderr
    assert not (tmp_path / "run" / "identify").exists()


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=12, max_size=80), st.floats(20, 1000), st.data())
def test_mad_outlier_flag_finds_a_planted_outlier(values, size, data):
    r = np.asarray(values) * 1e-5
    k = data.draw(st.integers(0, r.size - 1))
    r[k] = size * 1e-5 * data.draw(st.sampled_from([-1, 1])) + np.median(r)
    c = C.check_outliers("/c", r[:, None], np.arange(r.size) + 100, threshold=6.0)
    assert 100 + k in c.records


@settings(max_examples=30, deadline=None)
@given(st.lists(st.integers(0, 10**6), min_size=3, max_size=60, unique=True))
def test_stream_time_check_passes_increasing_times_and_names_a_swap(ts):
    t = np.cumsum(np.asarray(ts, np.int64) % 1000 + 1)
    rec = np.arange(t.size) // 2
    assert C.check_stream_time("/s", t, rec)[0].status == "pass"
    t2 = t.copy()
    t2[[1, 2]] = t2[[2, 1]]
    c = C.check_stream_time("/s", t2, rec)[0]
    assert c.status == "fail" and c.records == [int(rec[2])]


def test_thin_keeps_a_non_integral_value_for_integer_schemas():
    from pipeline.recording.schemas import validator

    v = validator("joint_state")
    msg = {"timestamp_ns": 1, "timestamps_ns": list(range(100)), "joint_names": ["a"], "positions": [[0.0]] * 100}
    assert v.is_valid(C.thin(msg))
    msg["timestamps_ns"][57] = 3.5
    assert not v.is_valid(C.thin(msg))
    _ = RobocalError
