"""CI reprocessing: a folder of recordings in parallel, compared with expected figures."""

from __future__ import annotations

import json
import math

from hypothesis import given
from hypothesis import strategies as st

from pipeline.stages.reprocess import check_figure, compare_expected
from tests.conftest import run_cli
from tests.pipeline_support import ROOT, base_campaign, write


@given(st.floats(1e-6, 1.0), st.floats(0.001, 0.5))
def test_relative_tolerance_rule(v, rel):
    rule = {"value": v, "rel_tol": rel}
    assert check_figure("x", rule, v * (1 + rel * 0.99)) is None
    assert "x = " in check_figure("x", rule, v * (1 + rel * 1.01) + 1e-12)


def test_rules_report_each_regression():
    exp = {"figures": {"n": {"equals": 10}, "rms": {"max": 1e-4}, "h": {"min": 0.5}, "s": {"equals": "pass"},
                       "gone": {"equals": 1}}}
    bad = compare_expected({"n": 9, "rms": 2e-4, "h": 0.4, "s": "pass"}, exp)
    assert len(bad) == 4 and any(b.startswith("gone") for b in bad)
    assert compare_expected({"n": 10, "rms": 5e-5, "h": 0.6, "s": "pass", "gone": 1}, exp) == []


def test_bundled_recording_has_expected_figures_matching_its_contract():
    exp = json.loads((ROOT / "recordings" / "arc-welder-touch.expected.json").read_text())
    assert {"rms_after_m", "holdout_rms_m", "n_identifiable", "status"} <= set(exp["figures"])


def test_reprocess_folder_passes_then_flags_a_regression_and_a_failing_recording(tmp_path):
    rec_dir, out = tmp_path / "recordings", tmp_path / "runs"
    rec_dir.mkdir()
    meta, js, contacts = base_campaign()
    write(rec_dir / "good.mcap", meta, js, contacts)
    expected = {"figures": {"n_measurements": {"equals": 40}, "status": {"equals": "pass"},
                            "rms_after_m": {"max": 1e-4}, "n_identifiable": {"min": 20}}}
    (rec_dir / "good.expected.json").write_text(json.dumps(expected))
    p = run_cli("reprocess", rec_dir, "--out", out, "--core")
    assert p.returncode == 0, p.stdout + p.stderr
    rows = json.loads((out / "summary.json").read_text())["rows"]
    assert rows[0]["system"] == "arc-welder" and rows[0]["n_measurements"] == 40 and rows[0]["ok"]
    assert (out / "summary.csv").read_text().startswith('"recording","robot_id","system"')

    expected["figures"]["rms_after_m"] = {"max": 1e-6}  # a result that no longer meets expectations
    (rec_dir / "good.expected.json").write_text(json.dumps(expected))
    contacts[9]["joint_positions"][4] = math.radians(140)  # and a recording that fails validation
    write(rec_dir / "bad.mcap", meta, js, contacts)
    p = run_cli("reprocess", rec_dir, "--out", out, "--core", "--workers", "2")
    assert p.returncode == 1
    rows = {r["recording"]: r for r in json.loads((out / "summary.json").read_text())["rows"]}
    assert any("rms_after_m" in r for r in rows["good.mcap"]["regressions"])  # kept by resume, gated anew
    from pipeline.fleet.dataset import read_results

    latest = {r["recording"]: r for r in read_results(out).to_pylist()}
    assert latest["good.mcap"]["regressions"] == rows["good.mcap"]["regressions"] and not latest["good.mcap"]["ok"]
    assert rows["bad.mcap"]["status"] == "fail" and "joint_limits" in rows["bad.mcap"]["error"]
    assert not rows["bad.mcap"]["ok"]
