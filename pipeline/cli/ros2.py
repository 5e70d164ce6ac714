"""`robocal import ros2`: a ROS 2 bag (JointState + PointStamped/PoseStamped) → a robocal recording."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from pipeline.cli import bag_options
from pipeline.cli.importer import import_app

BAG = bag_options.options()


@import_app.command("ros2")
def import_ros2(
    bag: Path = typer.Argument(..., help="ROS 2 bag: a folder with metadata.yaml, or its .mcap or .db3 file."),
    urdf: Path = typer.Option(..., "--urdf", help="Robot description (URDF); meshes are not needed."),
    root: str = typer.Option(..., "--root", help="Root link of the calibrated chain."),
    tip: Optional[str] = typer.Option(None, "--tip", help="Tip link of the calibrated chain (not with "
                                      "--measure-topic LINK=TOPIC, whose links are the tips)."),
    out: Path = typer.Option(..., "--out", help="Recording to write (MCAP)."),
    joint_topic: str = BAG["joint_topic"],
    measure_topic: Optional[list[str]] = BAG["measure_topic"], coupled: Optional[list[str]] = BAG["coupled"],
    measure: Optional[str] = BAG["measure"], window_s: float = BAG["window_s"], max_speed: float = BAG["max_speed"],
    time: str = BAG["time"], sigma_m: float = BAG["sigma_m"], sigma_rad: float = BAG["sigma_rad"],
    robot_id: str = typer.Option("", "--robot-id", help="Robot identity (name or serial) stored in the campaign."),
) -> None:
    """Pair each measurement with the joint state where the robot stood still around it and write a
    recording `robocal run` calibrates; measurements taken while moving are listed and left out."""
    from pipeline.importers.bag_import import import_bag
    from pipeline.importers.ros2 import BagSpec

    mt, tips = bag_options.measure_topics(measure_topic, tip)
    spec = BagSpec(joint_topic=joint_topic, measure_topic=mt, measure=measure, window_s=window_s,
                   max_speed=max_speed, time=time, tips=tips)
    done = import_bag(bag, urdf, root, tip, out, spec, sigma_m, sigma_rad, robot_id, on_read=bag_options.print_read,
                      coupled=tuple(coupled or ()))
    bag_options.print_written(done)
