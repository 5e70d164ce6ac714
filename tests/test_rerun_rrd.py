"""run.rrd read back with rerun's own reader (rerun.chunk.RrdReader): entities and their content
checked against the run's artefacts and an independent recomputation from the recording."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from rerun.chunk import RrdReader

from pipeline.models import serial_arm
from pipeline.recording.reader import read_recording
from pipeline.systems.registry import detect
from report_support import _RUN, report_run  # noqa: F401  (session fixture)


def _read(path: Path) -> dict[str, dict]:
    """entity path -> {"static": {component: [values]}, "timelines": set, "rows": {component: [rows]},
    "index": {timeline: [values]}} gathered over every chunk of the recording store."""
    out: dict[str, dict] = defaultdict(lambda: {"static": {}, "rows": defaultdict(list), "index": defaultdict(list)})
    for chunk in RrdReader(path).stream():
        b = chunk.to_record_batch()
        e = out[chunk.entity_path.lstrip("/")]
        for name in b.schema.names:
            if "RowId" in name:
                continue
            arr = b.column(name)
            if pa.types.is_timestamp(arr.type) or pa.types.is_duration(arr.type):  # ns, as int64
                arr = arr.cast(pa.int64())
            col = arr.to_pylist()
            if name in chunk.timeline_names:
                e["index"][name] += col
            elif chunk.is_static:
                e["static"][name] = col[-1]
            else:
                e["rows"][name] += col
    return out


@pytest.fixture(scope="module")
def rrd(report_run) -> dict[str, dict]:  # noqa: F811
    path = report_run / "run.rrd"
    assert path.is_file() and path.stat().st_size > 10_000
    return _read(path)


@pytest.fixture(scope="module")
def truth(report_run):  # noqa: F811
    """Model and table rebuilt independently from the source recording, and fit.json."""
    rec = read_recording(_RUN["recording"])
    model, table = detect(rec).load(rec)
    fit = json.loads((report_run / "identify" / "fit.json").read_text())
    return model, table, fit


def test_entities_present(rrd):
    want = {"world/jig/blocks", "world/jig/faces", "world/tips/nominal", "world/tips/calibrated",
            "world/residuals/before", "world/residuals/after_x100", "world/robot/poses", "world/robot/live",
            "world/contacts", "encoder/joints", "solver/rms_mm", "summary"}
    missing = want - set(rrd)
    assert not missing, f"entities missing from run.rrd: {sorted(missing)}"
    assert any(e.startswith("residuals/after_mm/") for e in rrd)
    assert any(e.startswith("residuals/holdout_mm/") for e in rrd)


def test_tool_tips_match_the_calibrated_and_nominal_models(rrd, truth):
    model, table, fit = truth
    p1 = np.array(rrd["world/tips/calibrated"]["static"]["Points3D:positions"])
    p0 = np.array(rrd["world/tips/nominal"]["static"]["Points3D:positions"])
    want1 = serial_arm.tip_position(np.array(fit["x"]), table["joint_positions"])
    want0 = serial_arm.tip_position(np.array(fit["nominal"]), table["joint_positions"])
    assert p1.shape == want1.shape == (40, 3)
    np.testing.assert_allclose(p1, want1, atol=1e-6)  # stored as float32
    np.testing.assert_allclose(p0, want0, atol=1e-6)
    assert np.sqrt(np.mean(np.sum((p1 - p0) ** 2, axis=1))) > 1e-3  # calibration moved the tips by mm


def test_residual_arrows_follow_the_face_axes(rrd, report_run, truth):  # noqa: F811
    _, table, _ = truth
    res = pq.read_table(report_run / "identify" / "residuals.parquet").to_pydict()
    v = np.array(rrd["world/residuals/before"]["static"]["Arrows3D:vectors"])
    assert v.shape == (40, 3)
    axis = np.asarray(table["axis"])
    # each arrow lies along its face's axis, with length |residual before|
    np.testing.assert_allclose(np.abs(v[np.arange(40), axis]), np.abs(res["before_0"]), rtol=1e-5, atol=1e-9)
    off = v.copy()
    off[np.arange(40), axis] = 0
    assert np.all(off == 0)
    va = np.array(rrd["world/residuals/after_x100"]["static"]["Arrows3D:vectors"])
    np.testing.assert_allclose(-va[np.arange(40), axis] / 100, res["after_0"], rtol=1e-4, atol=1e-10)


def test_encoder_stream_on_the_recordings_timeline(rrd, report_run):  # noqa: F811
    enc = pq.read_table(report_run / "ingest" / "encoder.parquet").to_pydict()
    e = rrd["encoder/joints"]
    t = np.array(e["index"]["time"], np.int64)
    q = np.array(e["rows"]["Scalars:scalars"])
    order = np.argsort(t, kind="stable")
    assert t.size == len(enc["t_ns"])
    np.testing.assert_array_equal(t[order], np.asarray(enc["t_ns"]))
    np.testing.assert_allclose(q[order][:, 1], enc["q_J2"])
    assert len(e["static"]["SeriesLines:names"]) == 6


def test_solver_iterations_on_a_sequence_timeline(rrd, report_run):  # noqa: F811
    hist = json.loads((report_run / "identify" / "history.json").read_text())
    hist = hist["cost_rms_m"] if isinstance(hist, dict) else hist
    s = rrd["solver/rms_mm"]
    assert s["index"]["iteration"] == list(range(len(hist)))
    np.testing.assert_allclose(np.array(s["rows"]["Scalars:scalars"]).ravel(), np.array(hist) * 1e3)


def test_robot_and_jig_geometry(rrd, truth):
    model, table, fit = truth
    strips = rrd["world/robot/poses"]["static"]["LineStrips3D:strips"]
    assert 2 <= len(strips) <= 5
    tips = serial_arm.tip_position(np.array(fit["x"]), table["joint_positions"])
    base = serial_arm.frames(np.array(fit["x"]), table["joint_positions"][:1])[0, 0, :3, 3]
    for s in strips:
        s = np.array(s)
        assert s.shape == (8, 3)  # base, 6 joint frames, tool
        np.testing.assert_allclose(s[0], base, atol=1e-6)
        assert np.min(np.linalg.norm(tips - s[-1], axis=1)) < 1e-6  # ends at a measured tool tip
    live = rrd["world/robot/live"]
    assert len(live["index"]["time"]) > 100  # follows the encoder stream
    boxes = rrd["world/jig/blocks"]["static"]
    tops = sorted(np.array(boxes["Boxes3D:centers"])[:, 2] + np.array(boxes["Boxes3D:half_sizes"])[:, 2])
    np.testing.assert_allclose(tops, [0.06, 0.10, 0.14], atol=1e-6)
    assert len(rrd["world/jig/faces"]["static"]["LineStrips3D:labels"]) == 9


def test_blueprint_lays_out_the_views(report_run):  # noqa: F811
    r = RrdReader(report_run / "run.rrd")
    assert r.recordings() and r.blueprints()
    kinds, origins = set(), set()
    for chunk in r.stream(store=r.blueprints()[0]):
        b = chunk.to_record_batch()
        if "ViewBlueprint:class_identifier" in b.schema.names:
            kinds |= {v for row in b.column("ViewBlueprint:class_identifier").to_pylist() for v in row}
            origins |= {v for row in b.column("ViewBlueprint:space_origin").to_pylist() for v in row}
        if "TimePanelBlueprint:timeline" in b.schema.names:
            assert b.column("TimePanelBlueprint:timeline").to_pylist()[-1] in ("time", ["time"])
    assert {"3D", "TimeSeries"} <= kinds, kinds
    # before and after in separate views (their scales differ by orders of magnitude), and the accuracy verdict
    assert {"/world", "/encoder", "/residuals/before_mm", "/residuals/after_mm", "/solver", "/accuracy"} <= origins, origins


def test_artefacts_shaped_as_the_documented_contract(report_run, tmp_path):  # noqa: F811
    """The report also reads artefacts written exactly as docs/reference/artefacts.md describes them
    (q_<joint> columns, history as a list, sha256 at the top of recording.json)."""
    from pipeline.report.artefacts import load_run
    from pipeline.report.html import diagnosis_section
    from pipeline.report.stage import run
    from report_support import make_run

    d = make_run(_RUN["recording"], tmp_path / "run", diagnosis=True)
    out = run(d, {"html": False})
    assert out["n_measurements"] == 40 and out["rms_after_m"] < out["rms_before_m"] / 10
    art = load_run(d)
    assert set(art.joint_columns()) == {f"J{i}" for i in range(1, 7)} and len(art.history) > 3
    assert "fig-diagnosis-0" in diagnosis_section(art)
    rrd = _read(d / "run.rrd")
    assert {"world/jig/blocks", "world/tips/calibrated", "world/robot/live", "encoder/joints", "diagnosis"} <= set(rrd)
    plots = [e for e in rrd if e.startswith("diagnosis/plots/")]
    series = [e for e in plots if e.rsplit("/", 1)[-1] in ("before", "after")]
    assert len(series) == 2 and all(len(rrd[e]["rows"]["Scalars:scalars"]) == 40 for e in series)
