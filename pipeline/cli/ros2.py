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
    measure_topic: Optional[list[str]] = typer.Option(None, "--measure-topic", help="PointStamped / PoseStamped "
                                                      "topic (default: the bag's only one); a robot measured on "
                                                      "several links: LINK=TOPIC, repeated (one PointStamped topic "
                                                      "per tip)."),
    coupled: Optional[list[str]] = typer.Option(None, "--coupled", help="A joint driven by others, not in the "
                                                "JointStates: JOINT=EXPR, e.g. torso_3=-torso_1-torso_2 "
                                                "(repeatable; URDF <mimic> joints are coupled already)."),
    measure: Optional[str] = BAG["measure"], window_s: float = BAG["window_s"], max_speed: float = BAG["max_speed"],
    time: str = BAG["time"], sigma_m: float = BAG["sigma_m"], sigma_rad: float = BAG["sigma_rad"],
    robot_id: str = typer.Option("", "--robot-id", help="Robot identity (name or serial) stored in the campaign."),
) -> None:
    """Pair each measurement with the joint state where the robot stood still around it and write a
    recording `robocal run` calibrates; measurements taken while moving are listed and left out."""
    from pipeline.importers.bag_import import import_bag
    from pipeline.importers.ros2 import BagSpec

    from pipeline.errors import RobocalError

    topics = list(measure_topic or [])
    tips = tuple(tuple(p.strip() for p in t.split("=", 1)) for t in topics if "=" in t)
    if tips and (len(tips) != len(topics) or any(not a or not b for a, b in tips)):
        raise RobocalError("--measure-topic: with several tips, each is LINK=TOPIC (e.g. left_hand=/mocap/left)")
    if len(topics) > 1 and not tips:
        raise RobocalError("--measure-topic: given several times, each is LINK=TOPIC (one topic per tip)")
    if tips and tip is not None:
        raise RobocalError("--tip and --measure-topic LINK=TOPIC: the tips are the links of --measure-topic")
    if not tips and tip is None:
        raise RobocalError("--tip LINK is needed (or --measure-topic LINK=TOPIC per measured link)")
    if len({a for a, _ in tips}) != len(tips):
        raise RobocalError("--measure-topic: a link is given twice")
    spec = BagSpec(joint_topic=joint_topic, measure_topic=None if tips else (topics[0] if topics else None),
                   measure=measure, window_s=window_s, max_speed=max_speed, time=time, tips=tips)
    done = import_bag(bag, urdf, root, tip, out, spec, sigma_m, sigma_rad, robot_id, on_read=bag_options.print_read,
                      coupled=tuple(coupled or ()))
    bag_options.print_written(done)
