"""A ROS 2 bag → a robocal recording: the one way in (`import_bag`, for `robocal import ros2` and `robocal run
BAG`), and what `robocal run` reads (`run_input`: the recording itself, or the one imported from a bag into
DIR/import/recording.mcap).

The bag is opened once (`pipeline.ros2.bag.Bag`) and each of its messages decoded once: the robot's
description where the bag carries it, then one pass over the joint states and the measurement topics
(point / pose: `pipeline.ros2.points`; several measured tips: `pipeline.ros2.tips`); for a dynamics bag
(``--measure effort``) one pass over the joint states with their efforts (`pipeline.ros2.effort`); for a
camera bag, the joint states, CameraInfo and image stamps, and a second pass over the same open bag decoding
only the paired images (`pipeline.ros2.camera`, `pipeline.ros2.camera_import`).

The robot: `Robot.urdf` a URDF file, a ``.xacro`` (expanded by the xacro package, its ``$(find …)`` and
``package://`` resolved through ROS_PACKAGE_PATH / AMENT_PREFIX_PATH where set), or None — the bag's own
``/robot_description`` (what ``robot_state_publisher`` latched while recording).  Nothing prints here: what
was read, paired and written goes to `say` as lines (`pipeline.ros2.report`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from pipeline.errors import RobocalError
from pipeline.ros2.bag import Bag
from pipeline.ros2.kind import ros2_kind
from pipeline.ros2.points import BagSpec
from pipeline.ros2.report import Say, quiet, read_lines, written_lines


@dataclass(frozen=True)
class Robot:
    """The robot of a bag: its URDF (a file, a ``.xacro``, or None: the bag's ``/robot_description``), the
    calibrated chain's root link and tip link (None with several measured tips, `BagSpec.tips`), the
    ``J=EXPR`` couplings of joints the bag does not read, and whether a coupling replaces readings."""

    urdf: Path | None
    root: str
    tip: str | None
    coupled: tuple[str, ...] = ()
    coupling_wins: bool = False


@dataclass(frozen=True)
class BagImport:
    """What one import wrote: `n` measurements of `kind` (point | pose | camera; effort: `n` joint states) of `n_joints` joints
    (`root` → `tip`) into `out`; `ros2` the campaign's ROS 2 record (topics, frame, pairing);
    `n_stream` joint states whose efforts were kept in the encoder stream (None: no efforts); `robot_from`
    where the URDF came from."""

    out: Path
    n: int
    kind: str
    n_joints: int
    root: str
    tip: str
    ros2: dict = field(default_factory=dict)
    n_stream: int | None = None
    robot_from: str = ""


def urdf_text(bag: Bag, urdf: Path | None) -> tuple[str, str]:
    """(URDF text, where it came from) of the robot: the file (a ``.xacro`` expanded), or the bag's own
    ``/robot_description``."""
    if urdf is None:
        text = bag.description()
        if text is None:
            raise RobocalError(f"{bag.path}: the bag has no /robot_description (std_msgs/msg/String) to read the robot "
                               "from; give it as --urdf ROBOT.urdf (or ROBOT.urdf.xacro)")
        return text, f"{bag.path}#/robot_description"
    urdf = Path(urdf)
    if urdf.name.endswith(".xacro"):
        return xacro_text(urdf), str(urdf)
    try:
        return urdf.read_text(), str(urdf)
    except OSError as e:
        raise RobocalError(f"{urdf}: cannot read ({e.strerror or e})") from None
    except UnicodeDecodeError:
        raise RobocalError(f"{urdf}: not a text file (a URDF is XML)") from None


def xacro_text(path: Path) -> str:
    """The URDF a ``.xacro`` file expands to (the xacro package; default arguments)."""
    try:
        import xacro
    except ImportError:  # pragma: no cover — a dependency
        raise RobocalError(f"{path}: reading .xacro needs the xacro package (pip install xacro)") from None
    try:
        doc = xacro.process_file(str(path))
    except Exception as e:  # noqa: BLE001 — xacro's errors (XacroException, XML, a missing include) are the file's
        raise RobocalError(f"{path}: xacro cannot expand it ({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''})") from None
    return doc.toxml()


def describe(text: str, source: str, robot: Robot, spec: BagSpec):
    """(RobotDescription of the chain or tree, coupled joints) of the URDF text."""
    from pipeline.models import urdf as urdf_mod

    tips = [link for link, _ in spec.tips] or None
    if tips or robot.coupled:
        from pipeline.importers.tree_description import tree_description_text

        return tree_description_text(text, source, robot.root, tips or [robot.tip], list(robot.coupled))
    return urdf_mod.parse(text, robot.root, robot.tip, source=source), {}


def import_bag(path: Path, robot: Robot, out: Path, spec: BagSpec = BagSpec(), camera=None, sigma_m: float = 1e-3,
               sigma_rad: float = 1e-3, robot_id: str = "", force: bool = False, say: Say = quiet,
               effort=None) -> BagImport:
    """Read the bag `path` (module docstring), pair each measurement with the joint state where the robot
    stood still around it, and write the recording `out`.  `camera`: a `pipeline.ros2.camera.CameraSpec`
    for a camera bag.  ``spec.measure == "effort"``: every joint state with its efforts, a dynamics recording
    declared by `effort` (a `pipeline.importers.effort_recording.EffortSpec`).  Pose measurements carry
    `sigma_m` (m) and `sigma_rad` (rad).  A coupled joint the JointStates carry too is an error unless
    `robot.coupling_wins` (the coupling replaces its readings).  An existing recording at `out` is replaced
    only with `force` (kept as NAME.bak)."""
    from pipeline.importers.effort_recording import EffortSpec
    from pipeline.recording.output import check_output

    path, out = Path(path), Path(out)
    if out.exists() and out.resolve() == path.resolve():
        raise RobocalError(f"{out}: --out is the bag itself")
    if spec.measure != "effort" and effort is not None and effort != EffortSpec():
        raise RobocalError("--effort-* and --position-* options apply to "
                           "--measure effort only")
    check_output(out, force=force)  # before the bag is read
    if spec.measure == "effort":
        return _import_effort(path, robot, out, spec, camera, effort or EffortSpec(), robot_id, force, say)
    if camera is not None:
        from pipeline.ros2.camera_import import check_camera

        check_camera(camera)
    with Bag(path) as bag:
        text, source = urdf_text(bag, robot.urdf)
        desc, cp = describe(text, source, robot, spec)
        if camera is not None:
            from pipeline.ros2.camera_import import import_camera

            n = import_camera(bag, desc, out, spec, camera, robot_id, force=force, say=say)
            return BagImport(out, n, "camera", len(desc.joint_names), desc.root, desc.tip, robot_from=source)
        from pipeline.ros2.points import read_bag

        table, extras = read_bag(bag, desc, spec)
    return _write(path, out, desc, cp, spec, table, extras, robot, sigma_m, sigma_rad, robot_id, force, say, source)


def _import_effort(path, robot, out, spec, camera, effort, robot_id, force, say) -> BagImport:
    """A dynamics recording of every joint state of the bag with its positions, velocities and efforts."""
    from pipeline.importers.effort_recording import write_effort_recording
    from pipeline.importers.joint_readings import declaration
    from pipeline.models import urdf as urdf_mod
    from pipeline.recording.output import claim_output
    from pipeline.ros2.effort import read_efforts

    if robot.tip is None or spec.measure_topic or spec.tips or camera is not None or robot.coupled:
        raise RobocalError("--measure effort needs --tip LINK and takes no --measure-topic, --target or --coupled")
    with Bag(path) as bag:
        text, source = urdf_text(bag, robot.urdf)
        desc = urdf_mod.parse(text, robot.root, robot.tip, source=source)
        pos_doc = declaration(effort.positions, desc.joint_names)
        logs = read_efforts(bag, desc, spec.joint_topic, spec.time, pos_doc)
    claim_output(out, force=force)  # with --force the old recording kept as NAME.bak
    write_effort_recording(out, desc, logs, source, effort,
                           {"source_files": [str(path)], **({"positions": pos_doc} if pos_doc else {})}, robot_id, say)
    return BagImport(out, len(logs["t_ns"]), "effort", len(desc.joint_names), desc.root, desc.tip,
                     robot_from=source)


def _write(path, out, desc, cp, spec, table, extras, robot, sigma_m, sigma_rad, robot_id, force, say, source):
    from pipeline.importers.recording import write_urdf_recording
    from pipeline.recording.output import claim_output

    carried = [c for c in cp if c in extras["ros2"]["joint_states"]["ignored_joints"]]
    if carried and not robot.coupling_wins:
        c = carried[0]
        raise RobocalError(f"{path}: topic {extras['ros2']['joint_topic']}: joint {c!r} is given to --coupled but the "
                           f"JointStates carry its readings; drop --coupled {c} (the readings win) or add "
                           "--coupling-wins (the coupling replaces them)")
    kind = "pose" if "orientation" in table else "point"
    if cp and kind != "point":
        raise RobocalError(f"{path}: --coupled needs point measurements (the topic gives {kind})")
    tips = [link for link, _ in spec.tips] or None
    campaign = {**extras, "robot_id": robot_id or desc.name, **({"coupled": cp} if cp else {})}
    if kind == "pose":
        campaign |= {"sigma_m": sigma_m, "sigma_rad": sigma_rad}
    read_lines(path, extras, say)
    stream = table.pop("stream", None)
    claim_output(out, force=force)  # with --force the old recording kept as NAME.bak
    n = write_urdf_recording(out, desc, kind, campaign, table, stream=stream, tips=tips)
    done = BagImport(out=out, n=n, kind=kind, n_joints=len(desc.joint_names), root=desc.root,
                     tip=", ".join(tips) if tips else desc.tip, ros2=extras["ros2"],
                     n_stream=None if stream is None else len(stream["t_ns"]), robot_from=source)
    written_lines(done, say)
    return done


def run_input(recording: Path, out: Path, robot: Robot | None, spec: BagSpec = BagSpec(), camera=None,
              sigma_m: float = 1e-3, sigma_rad: float = 1e-3, say: Say = quiet, effort=None) -> Path:
    """What `robocal run` reads: `recording` itself, or — for a ROS 2 bag — the recording imported from it
    into DIR/import/recording.mcap (re-imported each run: bit-identical, so the stages after it stay
    cached).  Bag options without a bag, or a bag without its chain, are one-line errors."""
    from pipeline.stages.runfolder import claim, fresh_stage_dir, locked, record_manifest

    given = [] if robot is None else [f"--{k}" for k, v in (("urdf", robot.urdf), ("root", robot.root),
                                                          ("tip", robot.tip or spec.tips)) if v]
    if ros2_kind(recording) is None:
        if given or spec.measure_topic or camera is not None or effort is not None or (
                robot is not None and (robot.coupled or robot.coupling_wins)):
            raise RobocalError(f"{recording}: is not a ROS 2 bag; --urdf/--root/--tip/--measure-topic/--target/"
                               "--coupled/--effort-*/--position-* apply to ROS 2 bags only")
        return recording
    if robot is None or not robot.root or not (robot.tip or spec.tips):
        raise RobocalError(f"{recording}: is a ROS 2 bag: give the robot's chain as --root LINK --tip LINK (and "
                           "--urdf ROBOT.urdf unless the bag carries /robot_description; --measure-topic TOPIC, or "
                           "--measure-topic LINK=TOPIC per measured link; docs/guide/import-ros2.md)")
    with locked(out):
        claim(out)
        d = fresh_stage_dir(out, "import")
        rec = d / "recording.mcap"
        try:
            import_bag(recording, robot, rec, spec, camera, sigma_m, sigma_rad, say=say, effort=effort)
        finally:
            record_manifest(d)  # what robocal wrote there, so a rerun replaces only that
    return rec
