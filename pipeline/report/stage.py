"""The report stage: DIR/report.html and DIR/run.rrd from the artefacts of the stages before it.

``run(run_dir, params) -> dict`` is called by the pipeline (`robocal run`, `robocal report`);
it returns the report's machine-readable figures for results.json.

Parameters (all optional): ``rrd`` (bool, default True: write run.rrd), ``html`` (bool, default
True), ``recording`` (path of the source MCAP, used only when the artefacts alone cannot rebuild
the measurement model for the 3-D scene).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pipeline import __version__
from pipeline.report.artefacts import load_run
from pipeline.report.figures import results_figures
from pipeline.report.html import render

REPORT_HTML = "report.html"
RUN_RRD = "run.rrd"


def run(run_dir: Path, params: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write DIR/report.html and DIR/run.rrd; return the figures (SI) for results.json."""
    run_dir = Path(run_dir)
    params = dict(params or {})
    from pipeline.dynamics.stage import is_dynamics_run

    if is_dynamics_run(run_dir):  # torques measured vs predicted, residuals, parameters (pipeline.report.dynamics)
        from pipeline.report.dynamics import write_report

        return write_report(run_dir, params, REPORT_HTML, RUN_RRD)
    art = load_run(run_dir)
    figures = results_figures(art)
    out: dict[str, Any] = {**figures, "files": {}}
    shown = {k: v for k, v in params.items() if k != "recording"}
    from pipeline.progress import Ticker

    tick = Ticker("report", total=7 * bool(params.get("html", True)) + bool(params.get("rrd", True)), unit="parts")
    if params.get("html", True):
        html_path = run_dir / REPORT_HTML
        html_path.write_text(render(art, __version__, shown, RUN_RRD if params.get("rrd", True) else None, tick),
                             encoding="utf-8")
        out["files"]["html"] = REPORT_HTML
    if params.get("rrd", True):
        from pipeline.visualize.rrd import write_rrd

        info = write_rrd(art, run_dir / RUN_RRD, figures, params)
        tick("rerun recording")
        out["files"]["rrd"] = RUN_RRD
        out["rrd_entities"] = info["entities"]
        out["rrd_system_hook"] = info["system_hook"]
        if info["warnings"]:
            out["warnings"] = info["warnings"]
    tick.done()
    out["outputs"] = sorted(out["files"].values())  # files outside DIR/report/ (for the runner's cache)
    return out  # timings live in stage.json (the runner's), never in results
