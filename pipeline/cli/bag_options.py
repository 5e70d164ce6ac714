"""The options of a ROS 2 bag import (topics, standstill pairing, pose σ) shared by `robocal import
ros2` and `robocal run BAG`, and how the command line tells what an import read and wrote.
Registers no command."""

from __future__ import annotations

import typer
from rich.markup import escape

from pipeline.cli import err
from pipeline.importers import standstill

RUN_PANEL = "Import (when REC is a ROS 2 bag or needs --urdf)"


def options(panel: str | None = None) -> dict[str, typer.models.OptionInfo]:
    """The bag options by parameter name, shown under help panel `panel` (None: the command's own)."""
    kw = {"rich_help_panel": panel}
    return {
        "joint_topic": typer.Option("/joint_states", "--joint-topic", help="sensor_msgs/msg/JointState topic.", **kw),
        "measure_topic": typer.Option(None, "--measure-topic", help="geometry_msgs/msg/PointStamped or PoseStamped "
                                      "topic (default: the bag's only one); a robot measured on several links: "
                                      "LINK=TOPIC, repeated (one PointStamped topic per tip).", **kw),
        "coupled": typer.Option(None, "--coupled", help="A joint driven by others, not in the JointStates: "
                                "JOINT=EXPR, e.g. torso_3=-torso_1-torso_2, lift=0.01[m/rad]*j1 (a factor between a "
                                "prismatic and a revolute joint carries its unit; repeatable; URDF <mimic> joints are "
                                "coupled already).", **kw),
        "coupling_wins": typer.Option(False, "--coupling-wins", help="A --coupled joint the JointStates also carry: the "
                                      "coupling replaces its readings (without this that is an error).", **kw),
        "measure": typer.Option(None, "--measure", help="point, pose or effort (dynamics: every JointState with its "
                                "efforts).", show_default="from the topic's type", **kw),
        "window_s": typer.Option(standstill.DEFAULT_WINDOW_S, "--still-window-s", min=1e-6,
                                 help="Standstill window around each measurement, s.", **kw),
        "max_speed": typer.Option(standstill.DEFAULT_MAX_SPEED, "--still-speed-rad-s", min=1e-12,
                                  help="Largest joint speed (peak-to-peak over the window / window) still counted as "
                                       "standing still, rad/s (m/s for prismatic joints).", **kw),
        "time": typer.Option("header", "--time", help="Times from header (header.stamp; receive time for a topic "
                             "without stamps) or log (the bag's receive times).", **kw),
        "sigma_m": typer.Option(1e-3, "--sigma-m", help="Pose: position uncertainty, m.", **kw),
        "sigma_rad": typer.Option(1e-3, "--sigma-rad", help="Pose: orientation uncertainty, rad.", **kw),
    }


def effort_options(panel: str | None = None) -> dict[str, typer.models.OptionInfo]:
    """The effort declaration's options of a ``--measure effort`` bag (as `import csv --measure effort`), by
    parameter name, under help panel `panel`."""
    kw = {"rich_help_panel": panel}
    return {
        "effort_scale": typer.Option([], "--effort-scale", help="N·m (N) per raw effort unit, JOINT=K,… (as "
                                     "`import csv --measure effort`).", **kw),
        "effort_offset": typer.Option([], "--effort-offset", help="N·m (N) added, JOINT=C,…; C = weight: g × the "
                                      "mass the joint carries.", **kw),
        "effort_mix": typer.Option([], "--effort-mix", help="Raw efforts a joint's torque combines, JOINT=EXPR "
                                   "(repeatable).", **kw),
        "effort_joints": typer.Option("", "--effort-joints", help="Joints whose torque is fitted and scored "
                                      "(default: all).", **kw),
        "effort_units": typer.Option(None, "--effort-units", help="Nm (efforts are torques) or raw.",
                                     show_default="raw with a scale, else unknown", **kw),
        "position_scale": typer.Option([], "--position-scale", help="Positions that are not joint angles: rad (m) "
                                       "per raw unit, JOINT=K,… (as `import csv --measure effort`).", **kw),
        "position_offset": typer.Option([], "--position-offset", help="rad (m) added after scaling, JOINT=C,….",
                                        **kw),
        "position_mix": typer.Option([], "--position-mix", help="Raw positions a joint's angle combines, JOINT=EXPR "
                                     "(repeatable).", **kw),
    }


def effort_spec(scale, offset, mix, joints, units, positions=((), (), ())):
    """The `pipeline.importers.effort_recording.EffortSpec` of the effort options' values; `positions`: the
    values of --position-scale, --position-offset, --position-mix."""
    from pipeline.importers.effort_recording import EffortSpec
    from pipeline.importers.joint_readings import PositionSpec

    return EffortSpec(tuple(scale or ()), tuple(offset or ()), tuple(mix or ()), joints or "", units,
                      PositionSpec(*(tuple(x or ()) for x in positions)))


def measure_topics(measure_topic: list[str] | None, tip: str | None, bag: bool = True
                   ) -> tuple[str | None, tuple[tuple[str, str], ...]]:
    """(the one measurement topic or None, ((tip link, topic), …)) of the repeated --measure-topic values:
    one TOPIC (the chain's --tip), or LINK=TOPIC per measured link (the tree's tips).  `bag`: whether a tip
    is needed (a ROS 2 bag; `robocal run` of a recording needs none)."""
    from pipeline.errors import RobocalError

    topics = list(measure_topic or [])
    tips = tuple(tuple(p.strip() for p in t.split("=", 1)) for t in topics if "=" in t)
    if tips and (len(tips) != len(topics) or any(not a or not b for a, b in tips)):
        raise RobocalError("--measure-topic: with several tips, each is LINK=TOPIC (e.g. left_hand=/mocap/left)")
    if len(topics) > 1 and not tips:
        raise RobocalError("--measure-topic: given several times, each is LINK=TOPIC (one topic per tip)")
    if tips and tip is not None:
        raise RobocalError("--tip and --measure-topic LINK=TOPIC: the tips are the links of --measure-topic")
    if bag and not tips and tip is None:
        raise RobocalError("--tip LINK is needed (or --measure-topic LINK=TOPIC per measured link)")
    if len({a for a, _ in tips}) != len(tips):
        raise RobocalError("--measure-topic: a link is given twice")
    return (None if tips else (topics[0] if topics else None)), tips


def say(line: str) -> None:
    """Print one line an import says (`pipeline.ros2.report`) on stderr, its ``warning:`` / ``excluded:`` word in
    yellow, the rest as written (no rich markup read into it)."""
    for word in ("warning:", "excluded:"):
        if line.startswith(word):
            err.print(f"[yellow]{word}[/]{escape(line[len(word):])}", highlight=False, soft_wrap=True)
            return
    err.print(escape(line), highlight=False, soft_wrap=True)
