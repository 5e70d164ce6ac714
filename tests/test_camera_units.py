"""A camera's residuals are px: every residual figure robocal prints for a camera recording says px, and
every other recording's figures stay m shown as mm (the same text as before)."""

import re

from pipeline.identify.complexity import Selection, explain
from pipeline.report.html import summary_section
from pipeline.report.labels import residual_display, residual_text

SUMMARY = {"system": "urdf", "rms_before_m": 0.0384, "rms_after_m": 0.0188, "holdout_rms_m": 0.0639,
           "max_abs_after_m": 0.0481, "sigma_m": 0.0193, "n_identifiable": 24, "n_parameters": 63,
           "n_measurements": 270, "n_rejected": 0, "loss": "linear", "solver_evaluations": 7}


def test_residual_text_px_for_a_camera_mm_otherwise():
    assert residual_display("px") == (1.0, "px") and residual_display(None) == (1e3, "mm")
    assert residual_text(0.0639, "px") == "0.0639 px"
    assert residual_text(6.39e-5, None) == "0.0639 mm" == residual_text(6.39e-5, "m")
    assert residual_text(None, "px", none="—") == "—"


def test_report_cards_of_a_camera_run_are_px():
    html = summary_section({**SUMMARY, "residual_unit": "px"}, [])
    cards = dict((k, v) for v, k in re.findall(r'<div class="v">([^<]*)</div><div class="k">([^<]*)</div>', html))
    for k, v in (("RMS before", "0.0384 px"), ("RMS after", "0.0188 px"), ("held-out RMS", "0.0639 px"),
                 ("max |residual| after", "0.0481 px"), ("residual σ", "0.0193 px")):
        assert cards[k] == v, (k, cards[k])
    mm = summary_section({**SUMMARY, "rms_after_m": 1.88e-5}, [])  # a length recording: m shown as mm
    assert '<div class="v">0.0188 mm</div><div class="k">RMS after</div>' in mm


def test_model_selection_explained_in_the_residuals_unit():
    sel = Selection(kept=["registration", "lens k3"], fixed=(), holdout_registration_m=0.94,
                    rounds=[{"candidate": "registration", "holdout_rms_m": 0.94, "kept": True},
                            {"candidate": "lens k3", "holdout_rms_m": 0.90, "against_m": 0.94, "kept": True}],
                    holdout_rms_m=0.90)
    assert explain(sel, "px") == ["registration only: held-out RMS 0.940 px",
                                  "+ lens k3: held-out 0.900 px against 0.940 px → kept"]
    assert explain(sel)[0] == "registration only: held-out RMS 940.000 mm"


def test_reprocess_table_shows_a_camera_row_in_px(tmp_path, capsys):
    """`robocal reprocess`'s table reads each run's fit.json: a camera run's figures say px, a length
    run's stay mm."""
    import json

    from pipeline.cli.reprocess import _print_table

    cam, arm = tmp_path / "cam", tmp_path / "arm"
    for d, unit in ((cam, "px"), (arm, None)):
        (d / "identify").mkdir(parents=True)
        (d / "identify" / "fit.json").write_text(json.dumps({"residual_unit": unit} if unit else {}))
    base = {"robot_id": "r", "system": "s", "n_measurements": 10, "n_identifiable": 3, "status": "pass",
            "expected": None, "regressions": [], "ok": True}
    rows = [base | {"recording": "cam.mcap", "run_dir": str(cam), "rms_before_m": 3.5, "rms_after_m": 0.94,
                    "holdout_rms_m": 1.02},
            base | {"recording": "arm.mcap", "run_dir": str(arm), "rms_before_m": 0.018, "rms_after_m": 3.5e-5,
                    "holdout_rms_m": 4.8e-5}]
    _print_table(tmp_path, rows)
    out = capsys.readouterr().out
    assert "0.9400 px" in out and "1.0200 px" in out and "0.0350" in out and "0.0350 px" not in out


def _fleet_rows(unit, holdout):
    par = [{"name": "fx", "unit": "px", "nominal": 600.0, "estimate": 600.0 + i * 1e-3, "std": 0.1,
            "identifiable": True} for i in range(1)]
    return [{"recording": f"c{i}.mcap", "robot_id": "cell", "campaign_start_ns": (1_700_000_000 + i * 86400) * 10**9,
             "status": "pass", "n_identifiable": 1, "residual_dof": 100, "parameters": par, "holdout_rms_m": h,
             "predicted_point_sigma_rms_m": None, "residual_unit": unit} for i, h in enumerate(holdout)]


def test_fleet_page_of_a_camera_cell_is_px_and_not_held_to_a_length_tolerance():
    """A camera cell's held-out figures are px: the fleet's accuracy plot says px, and a tolerance in
    metres (0.1 mm) does not flag 0.9 px as 'above tolerance'; a length robot's 0.2 mm still is."""
    from pipeline.fleet import plots
    from pipeline.fleet.history import robot_history

    cam = robot_history("cell", _fleet_rows("px", [0.91, 0.94, 0.90]), tolerance_m=1e-4)
    assert cam.tolerance == []
    svg = plots.accuracy(cam, 1e-4)
    assert re.findall(r">([^<]*(?:px|mm)[^<]*)<", svg) == ["px"]  # the axis label; no mm, no tolerance line
    arm = robot_history("arm", _fleet_rows(None, [5e-5, 2e-4]), tolerance_m=1e-4)
    assert [t["holdout_rms_m"] for t in arm.tolerance] == [2e-4]
    assert re.findall(r">([^<]*(?:px|mm)[^<]*)<", plots.accuracy(arm, 1e-4)) == ["mm", "tolerance 0.1 mm"]
