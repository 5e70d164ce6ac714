"""`robocal import ros2`: a ROS 2 bag (JointState + PointStamped/PoseStamped) → a robocal recording."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from pipeline.cli import err
from pipeline.cli.importer import import_app
from pipeline.importers import standstill

JOINT_TOPIC = typer.Option("/joint_states", "--joint-topic", help="sensor_msgs/msg/JointState topic.")
MEASURE_TOPIC = typer.Option(None, "--measure-topic", help="geometry_msgs/msg/PointStamped or PoseStamped topic "
                             "(default: the bag's only one).")
MEASURE = typer.Option(None, "--measure", help="point | pose (default: from the topic's type).")
WINDOW = typer.Option(standstill.DEFAULT_WINDOW_S, "--still-window", min=1e-6,
                      help="Standstill window around each measurement, s.")
SPEED = typer.Option(standstill.DEFAULT_MAX_SPEED, "--still-speed", min=1e-12,
                     help="Largest joint speed (peak-to-peak over the window / window) still counted as standing "
                          "still, rad/s (m/s for prismatic joints).")
TIME = typer.Option("header", "--time", help="Times from header (header.stamp; receive time for a topic without "
                    "stamps) or log (the bag's receive times).")
SIGMA_M = typer.Option(1e-3, "--sigma-m", help="Pose: position uncertainty, m.")
SIGMA_RAD = typer.Option(1e-3, "--sigma-rad", help="Pose: orientation uncertainty, rad.")


def import_bag(bag: Path, urdf: Path, root: str, tip: str, out: Path, joint_topic: str = "/joint_states",
               measure_topic: str | None = None, measure: str | None = None,
               window_s: float = standstill.DEFAULT_WINDOW_S, max_speed: float = standstill.DEFAULT_MAX_SPEED,
               time: str = "header", sigma_m: float = 1e-3, sigma_rad: float = 1e-3, robot_id: str = "") -> dict:
    """Read `bag`, pair, write the recording `out`; print the pairing and return the campaign's
    ``ros2`` record (topics, frame, pairing: window s, max speed, counts, excluded times)."""
    from pipeline.errors import RobocalError
    from pipeline.importers.recording import write_urdf_recording
    from pipeline.importers.ros2 import BagSpec, read_bag
    from pipeline.models import urdf as urdf_mod

    if out.exists() and out.resolve() == bag.resolve():
        raise RobocalError(f"{out}: --out is the bag itself")
    desc = urdf_mod.read(urdf, root, tip)
    spec = BagSpec(joint_topic=joint_topic, measure_topic=measure_topic, measure=measure, window_s=window_s,
                   max_speed=max_speed, time=time)
    table, extras = read_bag(bag, desc, spec)
    kind = "pose" if "orientation" in table else "point"
    campaign = {**extras, "robot_id": robot_id or desc.name}
    if kind == "pose":
        campaign |= {"sigma_m": sigma_m, "sigma_rad": sigma_rad}
    for w in extras.get("import_warnings", []):
        err.print(f"[yellow]warning:[/] {w}", highlight=False, soft_wrap=True)
    r = extras["ros2"]
    p = r["pairing"]
    js = r["joint_states"]
    if js.get("efforts_dropped"):
        err.print(f"[yellow]warning:[/] {js['efforts_dropped']}", highlight=False, soft_wrap=True)
    skipped = f", {js['n_skipped_other_joints']} naming only other joints skipped" if js["n_skipped_other_joints"] else ""
    err.print(f"{bag}: {js['n_used']} joint states on {r['joint_topic']} "
              f"(ignored joints: {', '.join(js['ignored_joints']) or 'none'}{skipped}), "
              f"{p['n_measurements']} measurements on {r['measure_topic']} in frame {r['frame_id']!r}", highlight=False,
              soft_wrap=True)
    err.print(f"standstill pairing (window {p['window_s']:g} s, max speed {p['max_speed_rad_s_or_m_s']:g} rad/s): "
              f"{p['n_paired']} paired, {p['n_moving']} taken while moving, {p['n_not_covered']} outside the joint "
              "states — excluded", highlight=False, soft_wrap=True)
    for e in p["moving"]:
        err.print(f"[yellow]excluded:[/] {r['measure_topic']} record {e['index']} at {e['t_s']:.3f} s: moving "
                  f"({e['joint']} {e['speed']:.3g} rad/s over the window)", highlight=False, soft_wrap=True)
    for e in p["not_covered"]:
        err.print(f"[yellow]excluded:[/] {r['measure_topic']} record {e['index']} at {e['t_s']:.3f} s: no joint "
                  "states around it", highlight=False, soft_wrap=True)
    listed = len(p["moving"]) + len(p["not_covered"])
    if listed < p["n_moving"] + p["n_not_covered"]:
        err.print(f"… and {p['n_moving'] + p['n_not_covered'] - listed} more excluded (all counted in the "
                  "recording's campaign metadata)", highlight=False)
    stream = table.pop("stream", None)
    n = write_urdf_recording(out, desc, kind, campaign, table, stream=stream)
    if stream is not None:
        err.print(f"kept the efforts of {len(stream['t_ns'])} joint states in the encoder stream", highlight=False)
    err.print(f"imported {n} {kind} measurements of {len(desc.joint_names)} joints ({desc.root} → {desc.tip}) "
              f"into {out}", highlight=False, soft_wrap=True)
    return r


@import_app.command("ros2")
def import_ros2(
    bag: Path = typer.Argument(..., help="ROS 2 bag: a folder with metadata.yaml, or its .mcap or .db3 file."),
    urdf: Path = typer.Option(..., "--urdf", help="Robot description (URDF); meshes are not needed."),
    root: str = typer.Option(..., "--root", help="Root link of the calibrated chain."),
    tip: str = typer.Option(..., "--tip", help="Tip link of the calibrated chain."),
    out: Path = typer.Option(..., "--out", help="Recording to write (MCAP)."),
    joint_topic: str = JOINT_TOPIC, measure_topic: Optional[str] = MEASURE_TOPIC, measure: Optional[str] = MEASURE,
    window_s: float = WINDOW, max_speed: float = SPEED, time: str = TIME,
    sigma_m: float = SIGMA_M, sigma_rad: float = SIGMA_RAD,
    robot_id: str = typer.Option("", "--robot-id", help="Robot identity (name or serial) stored in the campaign."),
) -> None:
    """Pair each measurement with the joint state where the robot stood still around it and write a
    recording `robocal run` calibrates; measurements taken while moving are listed and left out."""
    import_bag(bag, urdf, root, tip, out, joint_topic, measure_topic, measure, window_s, max_speed, time,
               sigma_m, sigma_rad, robot_id)


def run_input(recording: Path, out: Path, urdf: Path | None, root: str | None, tip: str | None, **bag) -> Path:
    """What `robocal run` reads: `recording` itself, or — for a ROS 2 bag — the recording imported
    from it into DIR/import/recording.mcap (re-imported each run: bit-identical, so the stages after
    it stay cached).  Bag options without a bag, or a bag without the robot, are one-line errors."""
    from pipeline.errors import RobocalError
    from pipeline.importers.bagkind import ros2_kind
    from pipeline.stages.runfolder import claim, fresh_stage_dir, locked

    given = [f"--{k}" for k, v in (("urdf", urdf), ("root", root), ("tip", tip)) if v is not None]
    if ros2_kind(recording) is None:
        if given or bag.get("measure_topic"):
            raise RobocalError(f"{recording}: is not a ROS 2 bag; --urdf/--root/--tip/--measure-topic apply to "
                               "ROS 2 bags only")
        return recording
    if len(given) < 3:
        raise RobocalError(f"{recording}: is a ROS 2 bag: give the robot as --urdf ROBOT.urdf --root LINK --tip LINK "
                           "(and --measure-topic TOPIC; docs/guide/import-ros2.md)")
    with locked(out):
        claim(out)
        d = fresh_stage_dir(out, "import")
        rec = d / "recording.mcap"
        import_bag(recording, urdf, root, tip, rec, **bag)
    return rec
