"""`robocal view DIR`: open DIR/run.rrd in the rerun viewer (or print how to, without a display)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import typer

from pipeline.cli import VIEW, app, err


LOCAL = "127.0.0.1"


def viewer_command(rrd: Path, bind: str = LOCAL) -> list[str]:
    """The command that opens `rrd` in the rerun viewer shipped with rerun-sdk; the viewer's own
    server listens on `bind` only (rerun's default would be every interface, 0.0.0.0)."""
    exe = shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))
    return [exe, "--bind", bind, str(rrd)]


def has_display() -> bool:
    """A graphical session is available (always on macOS/Windows; DISPLAY or WAYLAND_DISPLAY on Linux)."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


@app.command("view", rich_help_panel=VIEW)
def view_cmd(
    run_dir: Path = typer.Argument(..., help="Run folder with run.rrd, the .rrd file itself, or a raw recording (.mcap)."),
    print_only: bool = typer.Option(False, "--print", help="Print the path and viewer command instead of opening it."),
    bind: str = typer.Option(LOCAL, "--bind", help="Address the viewer's server listens on (default this machine "
                             "only; 0.0.0.0 or :: for every interface)."),
) -> None:
    """Open the run's rerun recording (3-D jig/robot/tool tips, encoder stream, residuals, solver), or a
    raw recording's robot and campaign (docs/guide/view.md)."""
    from pipeline.errors import RobocalError

    if run_dir.suffix == ".mcap":  # a raw recording: the robot as built and the campaign, with a layout
        from pipeline.visualize.raw import write_raw_rrd

        if not run_dir.is_file():
            raise RobocalError(f"{run_dir}: no such recording")
        rrd = write_raw_rrd(run_dir)
    else:
        rrd = run_dir if run_dir.suffix == ".rrd" else run_dir / "run.rrd"
    if not rrd.is_file():
        raise RobocalError(f"{rrd}: no rerun recording (run `robocal report {run_dir}` first)")
    cmd = viewer_command(rrd, bind)
    if print_only or not has_display():
        if not print_only:
            err.print("no display: not opening the viewer; run this where there is one:", highlight=False)
        print(rrd)
        print(" ".join(cmd))
        return
    subprocess.Popen(cmd, start_new_session=True)
    err.print(f"opened {rrd} in the rerun viewer", highlight=False)
