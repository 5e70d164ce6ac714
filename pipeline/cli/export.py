"""`robocal export ros2`: a recording → a ROS 2 bag (`pipeline.ros2.export`)."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.markup import escape

from pipeline.cli import IMPORT, app, err

export_app = typer.Typer(help="Take a recording out: a ROS 2 bag for ros2 bag play, RViz, Foxglove and rerun.",
                         no_args_is_help=True)
app.add_typer(export_app, name="export", rich_help_panel=IMPORT)


@export_app.command("ros2")
def export_ros2(
    recording: Path = typer.Argument(..., help="Recording (MCAP) robocal wrote (acquire, import, simulate)."),
    out: Path = typer.Option(..., "--out", help="ROS 2 bag folder to write (rosbag2, MCAP storage)."),
    force: bool = typer.Option(False, "--force", help="Replace a bag robocal exported there before, keeping the old "
                               "one as NAME.bak (never a folder robocal did not write; never over an existing .bak)."),
) -> None:
    """Write the recording as a ROS 2 bag: /robot_description, /tf_static, /joint_states, /tf and the
    measurements as standard messages (PointStamped, PoseStamped, CameraInfo + Image)."""
    from pipeline.ros2.export import export_bag

    done = export_bag(recording, out, force=force)
    for topic, (typename, n) in done.topics.items():
        err.print(f"{escape(topic)}: {n} {typename}", highlight=False, soft_wrap=True)
    if done.left_out:
        err.print(f"not exported (no standard ROS 2 message): {escape(', '.join(done.left_out))}", highlight=False,
                  soft_wrap=True)
    err.print(f"wrote the ROS 2 bag {escape(str(out))}", highlight=False, soft_wrap=True)
