"""`robocal report DIR`: report.html and run.rrd of a run folder (cached like every stage)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from pipeline.cli import CALIBRATE, app, err


@app.command("report", rich_help_panel=CALIBRATE)
def report_cmd(
    run_dir: Optional[Path] = typer.Argument(None, help="Run folder (after `robocal identify`/`observe`)."),
    out: Optional[Path] = typer.Option(None, "--out", help="Run folder (same as the argument)."),
    no_rrd: bool = typer.Option(False, "--no-rrd", help="Write report.html only, not run.rrd."),
    force: bool = typer.Option(False, "--force", help="Run even if cached."),
    mesh_path: Optional[list[Path]] = typer.Option(None, "--mesh-path", help="A folder where the URDF's "
                                                    "package://PKG/… meshes are (PKG/… inside it; repeatable; also "
                                                    "ROS_PACKAGE_PATH, AMENT_PREFIX_PATH): run.rrd draws them, "
                                                    "primitives where a mesh is not found."),
) -> None:
    """Write DIR/report.html (self-contained, opens offline) and DIR/run.rrd (rerun; `robocal view DIR`)."""
    from pipeline.errors import RobocalError
    from pipeline.stages.runner import run_stage

    d = run_dir or out
    if d is None:
        raise RobocalError("robocal report: give the run folder (robocal report DIR)")
    if not d.is_dir():
        raise RobocalError(f"{d}: no such run folder")
    params: dict = {"rrd": False} if no_rrd else {}
    if mesh_path:
        params["mesh_path"] = [str(p.resolve()) for p in mesh_path]
    run_stage(d, "report", params, force=force,
              log=lambda line: err.print(line, highlight=False))
    print(f"report: {d / 'report.html'}")
    if not no_rrd:
        print(f"rerun:  {d / 'run.rrd'}  (robocal view {d})")
