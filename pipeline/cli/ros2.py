"""`robocal import ros2`: a ROS 2 bag (JointState + PointStamped/PoseStamped, or with --target camera
images: Image/CompressedImage + CameraInfo) → a robocal recording."""

from __future__ import annotations

from pathlib import Path
from typing import Literal, Optional

import typer

from pipeline.cli import bag_options, force_option
from pipeline.cli.importer import import_app

BAG = bag_options.options()
CAM = "Camera (a bag with images: --target)"
DYN = "Dynamics (--measure effort: every JointState with its efforts)"
EFF = bag_options.effort_options(DYN)


@import_app.command("ros2")
def import_ros2(
    bag: Path = typer.Argument(..., help="ROS 2 bag: a folder with metadata.yaml, or its .mcap or .db3 file."),
    urdf: Optional[Path] = typer.Option(None, "--urdf", help="Robot description: a URDF or .xacro file (meshes are "
                                        "not needed); default: the bag's own /robot_description."),
    root: str = typer.Option(..., "--root", help="Root link of the calibrated chain."),
    tip: Optional[str] = typer.Option(None, "--tip", help="Tip link of the calibrated chain (not with "
                                      "--measure-topic LINK=TOPIC, whose links are the tips)."),
    out: Path = typer.Option(..., "--out", help="Recording to write (MCAP)."),
    joint_topic: str = BAG["joint_topic"],
    measure_topic: Optional[list[str]] = BAG["measure_topic"], coupled: Optional[list[str]] = BAG["coupled"],
    coupling_wins: bool = BAG["coupling_wins"],
    measure: Optional[Literal["point", "pose", "effort"]] = BAG["measure"], window_s: float = BAG["window_s"], max_speed: float = BAG["max_speed"],
    time: Literal["header", "log"] = BAG["time"], sigma_m: float = BAG["sigma_m"], sigma_rad: float = BAG["sigma_rad"],
    robot_id: str = typer.Option("", "--robot-id", help="Robot identity (name or serial) stored in the campaign."),
    target: Optional[str] = typer.Option(None, "--target", rich_help_panel=CAM, help="A camera bag: the board the "
                                         "images show, as for `import images` (chessboard:COLSxROWS:SQUARE_M | "
                                         "charuco:… | aprilgrid:…)."),
    image_topic: Optional[str] = typer.Option(None, "--image-topic", rich_help_panel=CAM, help="sensor_msgs Image or "
                                              "CompressedImage topic (default: the bag's only one)."),
    info_topic: Optional[str] = typer.Option(None, "--camera-info-topic", rich_help_panel=CAM, help="CameraInfo topic "
                                             "(default: the one beside the image topic, or the bag's only one)."),
    camera_on: Literal["tip", "world"] = typer.Option("tip", "--camera-on", rich_help_panel=CAM, help="tip (eye-in-hand; board fixed) or "
                                  "world (eye-to-hand; board on the tip)."),
    lens: Literal["pinhole", "fisheye"] = typer.Option("pinhole", "--lens", rich_help_panel=CAM, help="Lens model."),
    n_dist: int = typer.Option(0, "--distortion-terms", rich_help_panel=CAM, help="Pinhole: 4, 5 or 8 (default 8); "
                               "fisheye: 4."),
    max_edge_px: float = typer.Option(5.0, "--max-edge-px", rich_help_panel=CAM, help="A chessboard with edges wider "
                                      "than this (px) is blurred."),
    clock_bound: float = typer.Option(0.1, "--clock-offset-bound-s", rich_help_panel=CAM, min=0.0, help="How far the "
                                      "camera's clock may be off the joint states' (s): an image is paired only where "
                                      "the robot stood still for ± this around its stamp."),
    clock_offset: float = typer.Option(0.0, "--clock-offset-s", rich_help_panel=CAM, help="A known offset, camera clock "
                                       "− joint clock (s), taken off the image stamps."),
    workers: int = typer.Option(0, "--workers", min=0, rich_help_panel=CAM, help="Detection processes (0: the CPU count)."),
    kinematics_known: bool = typer.Option(False, "--kinematics-known", rich_help_panel=CAM, help="The joint states "
                                          "are exact (e.g. a measured flange pose as the joints of `robocal import "
                                          "images`' pose chain): only camera, hand-eye and board are fitted."),
    skip_bad: bool = typer.Option(False, "--skip-bad", rich_help_panel=CAM, help="Leave out images that cannot be "
                                  "read, of an unsupported encoding or of another size than CameraInfo (listed)."),
    force: bool = force_option(),
    effort_scale: list[str] = EFF["effort_scale"], effort_offset: list[str] = EFF["effort_offset"],
    effort_mix: list[str] = EFF["effort_mix"], effort_joints: str = EFF["effort_joints"],
    effort_units: Optional[Literal["Nm", "raw"]] = EFF["effort_units"],
    position_scale: list[str] = EFF["position_scale"], position_offset: list[str] = EFF["position_offset"],
    position_mix: list[str] = EFF["position_mix"],
) -> None:
    """Pair each measurement with the joint state where the robot stood still around it and write a
    recording `robocal run` calibrates; measurements taken while moving are listed and left out."""
    from pipeline.errors import RobocalError
    from pipeline.recording.output import check_output
    from pipeline.ros2.importer import Robot, import_bag
    from pipeline.ros2.points import BagSpec

    check_output(out, force=force)  # before any work: an existing recording only with --force
    cam = None
    if target is not None:  # a camera bag: Image / CompressedImage + CameraInfo + JointState
        from pipeline.ros2.camera import CameraSpec

        if tip is None or measure_topic or coupled:
            raise RobocalError("--target (a camera bag) needs --tip LINK (where the camera or board is) and takes no "
                               "--measure-topic or --coupled")
        cam = CameraSpec(target=target, image_topic=image_topic, info_topic=info_topic, mount=camera_on, lens=lens,
                         n_dist=n_dist or (8 if lens == "pinhole" else 4), max_edge_px=max_edge_px,
                         clock_bound_s=clock_bound, clock_offset_s=clock_offset, workers=workers, skip_bad=skip_bad,
                         kinematics_known=kinematics_known)
    mt, tips = bag_options.measure_topics(measure_topic, tip)
    spec = BagSpec(joint_topic=joint_topic, measure_topic=mt, measure=measure, window_s=window_s,
                   max_speed=max_speed, time=time, tips=tips)
    robot = Robot(urdf, root, tip, tuple(coupled or ()), coupling_wins)
    effort = bag_options.effort_spec(effort_scale, effort_offset, effort_mix, effort_joints, effort_units,
                                     (position_scale, position_offset, position_mix))
    import_bag(bag, robot, out, spec, cam, sigma_m, sigma_rad, robot_id, force=force, say=bag_options.say,
               effort=effort)
