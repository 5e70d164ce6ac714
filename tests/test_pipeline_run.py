"""The staged pipeline on the bundled recording: artefacts, caching, re-runs, reproducibility."""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from pipeline.identify.least_squares import FitOptions
from pipeline.identify.outliers import fit_rejecting
from pipeline.stages.artefacts import from_arrow, to_arrow
from pipeline.stages.runner import run_pipeline
from tests.pipeline_support import BUNDLED

CORE = ["ingest", "validate", "identify", "observe"]


@pytest.fixture(scope="session")
def first_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("pipe") / "run"
    run_pipeline(BUNDLED, out, stages=CORE)
    return out


def test_every_artefact_of_the_contract_is_written(first_run):
    d = first_run
    for f in ["ingest/encoder.parquet", "ingest/touch_contact.parquet", "ingest/measurements.parquet",
              "ingest/recording.json", "validate/validate.json", "identify/fit.json", "identify/residuals.parquet",
              "identify/history.json", "identify/model.json", "observe/observe.json", "results.json"]:
        assert (d / f).is_file(), f
    m = pq.read_table(d / "ingest/measurements.parquet")
    assert {"record", "timestamp_ns", "joint_positions_0", "face", "axis", "coordinate", "v_J1", "dir_J6",
            "time_since_start_s"} <= set(m.column_names)
    assert m.num_rows == 100
    enc = pq.read_table(d / "ingest/encoder.parquet")
    assert enc.num_rows > 100_000 and np.all(np.diff(enc.column("t_ns").to_numpy()) > 0)
    r = pq.read_table(d / "identify/residuals.parquet").to_pydict()
    assert set(r["group"]) <= {"top1", "top2", "top3", "riser12", "riser23", "end_low", "end_high", "front", "back"}
    fit = json.loads((d / "identify/fit.json").read_text())
    after = np.asarray(r["after_0"])
    assert np.isclose(np.sqrt(np.mean(after**2)), fit["rms_after_m"])
    assert fit["rms_after_m"] < 5e-5 < fit["rms_before_m"] / 100
    assert 3e-5 < fit["holdout_rms_m"] < 8e-5
    n_free = sum(fit["free"])
    assert np.asarray(fit["cov"]).shape == (n_free, n_free)
    obs = json.loads((d / "observe/observe.json").read_text())
    assert len(obs["singular_values"]) == n_free and len(obs["identifiable"]) == n_free
    assert 0 < obs["O2"] <= 1 and np.isclose(obs["O4"], obs["O2"] * obs["O3"])
    assert all(k in obs["dependencies"] for k, f in zip(fit["names"], fit["free"]) if not f)
    assert np.allclose(np.diag(obs["correlation"]), 1)
    res = json.loads((d / "results.json").read_text())
    assert res["summary"]["status"] == "pass" and res["summary"]["n_identifiable"] == n_free
    assert set(res["stages"]) == set(CORE)


def test_second_run_is_cached_and_fast(first_run):
    t0 = time.perf_counter()
    outs = run_pipeline(BUNDLED, first_run, stages=CORE)
    assert time.perf_counter() - t0 < 1.0
    assert all(o.cached for o in outs)


def test_changing_a_parameter_reruns_that_stage_and_the_later_ones(first_run, tmp_path):
    d = tmp_path / "run"
    shutil.copytree(first_run, d)
    outs = run_pipeline(BUNDLED, d, {"identify": {"loss": "soft_l1"}}, stages=CORE)
    assert [o.cached for o in outs] == [True, True, False, False]
    assert json.loads((d / "identify/fit.json").read_text())["loss"] == "soft_l1"
    # a deleted or altered output makes its stage run again
    (d / "observe" / "observe.json").write_text("{}")
    outs = run_pipeline(BUNDLED, d, {"identify": {"loss": "soft_l1"}}, stages=CORE)
    assert [o.cached for o in outs] == [True, True, True, False]


def test_outputs_are_bit_identical_across_runs(first_run, tmp_path):
    d = tmp_path / "again"
    run_pipeline(BUNDLED, d, stages=CORE)
    files = sorted(p.relative_to(first_run) for p in first_run.rglob("*") if p.is_file() and p.name != "stage.json")
    assert files == sorted(p.relative_to(d) for p in d.rglob("*") if p.is_file() and p.name != "stage.json")
    for f in files:
        assert (first_run / f).read_bytes() == (d / f).read_bytes(), f


def test_outlier_rejection_names_the_record_and_restores_the_fit(first_run):
    from pipeline.ingest.tables import model_columns
    from pipeline.stages.ingest import load_system, read_measurements

    _, model, _ = load_system(first_run)
    data = model_columns(read_measurements(first_run))
    data["coordinate"] = data["coordinate"].copy()
    data["coordinate"][[13, 58]] += [0.003, -0.002]  # two gross errors (3 mm, 2 mm)
    plain = fit_rejecting(model, data, FitOptions(), threshold=0)
    robust = fit_rejecting(model, data, FitOptions(), threshold=5.0)
    assert sorted(r["record"] for r in robust.rejected) == [13, 58]
    assert robust.fit.rms_after < 5e-5 < plain.fit.rms_after
    huber = fit_rejecting(model, data, FitOptions(loss="huber", f_scale=1e-4), threshold=0)
    assert np.abs(huber.fit.x - robust.fit.x).max() < np.abs(plain.fit.x - robust.fit.x).max()


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 30), st.integers(1, 5), st.data())
def test_measurement_tables_round_trip_through_arrow(n, k, data):
    vec = data.draw(hnp.arrays(np.float64, (n, k), elements=st.floats(-1e3, 1e3)))
    t = {"record": np.arange(n), "q": vec, "name_0": np.linspace(0, 1, n),
         "face": np.array(data.draw(st.lists(st.text(max_size=5), min_size=n, max_size=n)), dtype=object),
         "flag": data.draw(hnp.arrays(np.bool_, n))}
    back = from_arrow(to_arrow(t))
    assert set(back) == set(t)
    assert np.array_equal(back["q"], vec) and back["q"].shape == (n, k)
    assert list(back["face"]) == list(t["face"]) and np.array_equal(back["flag"], t["flag"])
    assert np.array_equal(back["name_0"], t["name_0"])


def test_cli_run_reports_every_stage_cached_on_the_second_run(first_run, tmp_path):
    from tests.conftest import run_cli

    d = tmp_path / "cli"
    shutil.copytree(first_run, d)
    p = run_cli("run", BUNDLED, "--out", d, "--stages", ",".join(CORE))
    assert p.returncode == 0, p.stderr
    for s in CORE:
        assert f"{s}: cached" in p.stderr
    assert "every stage cached" in p.stderr


def test_a_change_of_robocal_code_changes_every_stage_key(monkeypatch):
    from pipeline.stages import runner

    before = runner.stage_key("identify", {"loss": "linear"}, {"ingest": "abc"})
    assert before == runner.stage_key("identify", {"loss": "linear"}, {"ingest": "abc"})
    monkeypatch.setattr(runner, "code_fingerprint", lambda: "edited source")
    assert runner.stage_key("identify", {"loss": "linear"}, {"ingest": "abc"}) != before


def test_every_result_of_a_full_run_is_bit_identical(tmp_path):
    """All stages, diagnose and report included: everything but the timings (stage.json) and
    run.rrd (rerun gives every row a fresh id) is byte for byte the same in two runs."""
    a, b = tmp_path / "a", tmp_path / "b"
    run_pipeline(BUNDLED, a)
    run_pipeline(BUNDLED, b)
    skip = {"stage.json", "run.rrd"}
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file() and p.name not in skip)
    assert {"results.json", "report.html", "diagnose/diagnosis.json"} <= {f.as_posix() for f in files}
    assert files == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file() and p.name not in skip)
    for f in files:
        assert (a / f).read_bytes() == (b / f).read_bytes(), f


def test_diagnose_stage_reuses_the_decoded_encoder_stream(first_run, tmp_path):
    """The diagnose stage reads ingest's encoder.parquet instead of decoding the MCAP's JSON
    batches again: the stream is bit-identical, so is the diagnosis; a stale file is an error."""
    from pipeline.diagnose.stage import diagnose_recording
    from pipeline.errors import RobocalError
    from pipeline.ingest.streams import joint_stream
    from pipeline.recording.reader import read_recording
    from pipeline.stages.ingest import read_encoder

    rec = read_recording(BUNDLED)
    a, b = joint_stream(rec), read_encoder(first_run)
    assert a.names == b.names
    for f in ("t_ns", "q", "message_index"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
        assert getattr(a, f).dtype == getattr(b, f).dtype
    da = diagnose_recording(rec, stream=None)
    db = diagnose_recording(rec, stream=b)
    assert json.dumps(da, sort_keys=True) == json.dumps(db, sort_keys=True)
    stale = tmp_path / "run"
    shutil.copytree(first_run / "ingest", stale / "ingest")
    t = pq.read_table(stale / "ingest/encoder.parquet")
    pq.write_table(t.slice(0, t.num_rows - 1), stale / "ingest/encoder.parquet")
    with pytest.raises(RobocalError, match="encoder.parquet: does not match .*recording.json"):
        read_encoder(stale)


def test_later_stages_read_the_recording_without_the_encoder_stream(first_run):
    """Ingest decoded the encoder stream once; later stages re-read only the rest of the MCAP
    (every other channel's messages, metadata and model unchanged)."""
    from pipeline.ingest.streams import JOINT_STATE
    from pipeline.recording.reader import read_recording
    from pipeline.stages.ingest import load_system

    full = read_recording(BUNDLED)
    _, model, rec = load_system(first_run)
    assert full.messages.raw[JOINT_STATE] and rec.messages.raw[JOINT_STATE] == []
    assert {t: m for t, m in full.messages.raw.items() if t != JOINT_STATE} == \
        {t: m for t, m in rec.messages.raw.items() if t != JOINT_STATE}
    assert rec.metadata == full.metadata and rec.complete and model.parameter_names()
    # rebuilt from ingest's messages.parquet, not by decompressing the MCAP again
    assert (first_run / "ingest" / "messages.parquet").is_file()
    assert rec.log_times == {t: v for t, v in full.log_times.items() if t != JOINT_STATE}
    assert rec.schemas == full.schemas and list(rec.messages.raw) == list(full.messages.raw)
    assert rec.path == full.path and rec.profile == full.profile and rec.warnings == full.warnings
    _, _, rec_s = load_system(first_run, with_stream=True)
    assert rec_s.messages.raw[JOINT_STATE] == full.messages.raw[JOINT_STATE]


def test_a_damaged_messages_parquet_is_a_one_line_error(first_run, tmp_path):
    """Ingest's `messages.parquet` with a message missing, or not Parquet at all: the stage that
    reads it names the file and says to re-run ingest (no traceback, nothing silently dropped)."""
    from pipeline.errors import RobocalError
    from pipeline.stages.ingest import read_messages, recording_info

    run = tmp_path / "run"
    shutil.copytree(first_run / "ingest", run / "ingest")
    info = recording_info(run)
    p = run / "ingest" / "messages.parquet"
    assert read_messages(run, info) is not None
    t = pq.read_table(p)
    pq.write_table(t.slice(0, t.num_rows - 1), p)
    with pytest.raises(RobocalError, match=r"messages\.parquet: \d+ messages on .*recording\.json says \d+"):
        read_messages(run, info)
    p.write_bytes(b"not parquet")
    with pytest.raises(RobocalError, match=r"messages\.parquet: unreadable .*re-run ingest"):
        read_messages(run, info)
