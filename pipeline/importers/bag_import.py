"""A ROS 2 bag → a robocal recording (`robocal import ros2`), and what `robocal run` reads: the
recording itself, or the one imported from a bag into DIR/import/recording.mcap.

No printing here: the command line is told what was read (`on_read`, before the recording is
written) and what was written (the returned `BagImport`), and says it in its own words.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from pipeline.errors import RobocalError
from pipeline.importers.bagkind import ros2_kind
from pipeline.importers.ros2 import BagSpec


@dataclass(frozen=True)
class BagImport:
    """What one import wrote: `n` measurements of `kind` (point | pose) of `n_joints` joints
    (`root` → `tip`) into `out`; `ros2` the campaign's ROS 2 record (topics, frame, pairing);
    `n_stream` joint states whose efforts were kept in the encoder stream (None: no efforts)."""

    out: Path
    n: int
    kind: str
    n_joints: int
    root: str
    tip: str
    ros2: dict
    n_stream: int | None


def import_bag(bag: Path, urdf: Path, root: str, tip: str, out: Path, spec: BagSpec = BagSpec(),
               sigma_m: float = 1e-3, sigma_rad: float = 1e-3, robot_id: str = "",
               on_read: Callable[[Path, dict], None] | None = None, coupled: tuple[str, ...] = (),
               force: bool = False, coupling_wins: bool = False) -> BagImport:
    """Read `bag` (the chain `root` → `tip` of `urdf`), pair each measurement with the joint state
    where the robot stood still around it, and write the recording `out`.  `on_read(bag, extras)`
    sees the read's extras (warnings, the ``ros2`` record) before anything is written.  Pose
    measurements carry `sigma_m` (m) and `sigma_rad` (rad).  A tree (`spec.tips`: (link, topic) pairs, or
    `coupled`: ``J=EXPR`` texts): the chains root → each tip, the coupled joints driven by the others.
    A coupled joint the JointStates carry too is an error unless `coupling_wins` (the coupling replaces
    its readings).  An existing recording at `out` is replaced only with `force` (kept as NAME.bak)."""
    from pipeline.importers.recording import write_urdf_recording
    from pipeline.importers.ros2 import read_bag
    from pipeline.models import urdf as urdf_mod

    if out.exists() and out.resolve() == bag.resolve():
        raise RobocalError(f"{out}: --out is the bag itself")
    from pipeline.recording.output import check_output

    check_output(out, force=force)  # before the bag is read
    tips = [link for link, _ in spec.tips] or None
    cp: dict = {}
    if tips or coupled:
        from pipeline.importers.tree_description import tree_description

        desc, cp = tree_description(urdf, root, tips or [tip], list(coupled))
    else:
        desc = urdf_mod.read(urdf, root, tip)
    table, extras = read_bag(bag, desc, spec)
    carried = [c for c in cp if c in extras["ros2"]["joint_states"]["ignored_joints"]]
    if carried and not coupling_wins:
        c = carried[0]
        raise RobocalError(f"{bag}: topic {extras['ros2']['joint_topic']}: joint {c!r} is given to --coupled but the "
                           f"JointStates carry its readings; drop --coupled {c} (the readings win) or add "
                           "--coupling-wins (the coupling replaces them)")
    kind = "pose" if "orientation" in table else "point"
    if cp and kind != "point":
        raise RobocalError(f"{bag}: --coupled needs point measurements (the topic gives {kind})")
    campaign = {**extras, "robot_id": robot_id or desc.name, **({"coupled": cp} if cp else {})}
    if kind == "pose":
        campaign |= {"sigma_m": sigma_m, "sigma_rad": sigma_rad}
    if on_read is not None:
        on_read(bag, extras)
    stream = table.pop("stream", None)
    from pipeline.recording.output import claim_output

    claim_output(out, force=force)  # with --force the old recording kept as NAME.bak
    n = write_urdf_recording(out, desc, kind, campaign, table, stream=stream, tips=tips)
    return BagImport(out=out, n=n, kind=kind, n_joints=len(desc.joint_names), root=desc.root,
                     tip=", ".join(tips) if tips else desc.tip,
                     ros2=extras["ros2"], n_stream=None if stream is None else len(stream["t_ns"]))


def run_input(recording: Path, out: Path, urdf: Path | None, root: str | None, tip: str | None,
              spec: BagSpec = BagSpec(), sigma_m: float = 1e-3, sigma_rad: float = 1e-3,
              on_read: Callable[[Path, dict], None] | None = None,
              on_written: Callable[[BagImport], None] | None = None,
              importer: Callable[[Path], None] | None = None, coupled: tuple[str, ...] = (),
              coupling_wins: bool = False) -> Path:
    """What `robocal run` reads: `recording` itself, or — for a ROS 2 bag — the recording imported
    from it into DIR/import/recording.mcap (re-imported each run: bit-identical, so the stages after
    it stay cached).  `importer(out)`: writes that recording instead of `import_bag` (a camera bag,
    `robocal run BAG --target`).  Bag options without a bag, or a bag without the robot, are one-line errors."""
    from pipeline.stages.runfolder import claim, fresh_stage_dir, locked, record_manifest

    given = [f"--{k}" for k, v in (("urdf", urdf), ("root", root), ("tip", tip or spec.tips)) if v]
    if ros2_kind(recording) is None:
        if given or spec.measure_topic or importer is not None or coupled or coupling_wins:
            raise RobocalError(f"{recording}: is not a ROS 2 bag; --urdf/--root/--tip/--measure-topic/--target/"
                               "--coupled apply to ROS 2 bags only")
        return recording
    if len(given) < 3:
        raise RobocalError(f"{recording}: is a ROS 2 bag: give the robot as --urdf ROBOT.urdf --root LINK --tip LINK "
                           "(and --measure-topic TOPIC, or --measure-topic LINK=TOPIC per measured link; "
                           "docs/guide/import-ros2.md)")
    with locked(out):
        claim(out)
        d = fresh_stage_dir(out, "import")
        rec = d / "recording.mcap"
        done = None
        try:
            if importer is not None:
                importer(rec)
            else:
                done = import_bag(recording, urdf, root, tip, rec, spec, sigma_m, sigma_rad, on_read=on_read,
                                  coupled=coupled, coupling_wins=coupling_wins)
        finally:
            record_manifest(d)  # what robocal wrote there, so a rerun replaces only that
        if on_written is not None and done is not None:
            on_written(done)
    return rec
