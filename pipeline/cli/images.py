"""`robocal import images`: calibration-board images + the robot's joints or flange poses → a recording."""

from __future__ import annotations

from pathlib import Path

from typing import Literal

import typer

from pipeline.cli import err, force_option
from pipeline.cli.importer import import_app

BAD = ("unreadable", "too large", "wrong size", "no state")  # bad input: an error unless --skip-bad


@import_app.command("images")
def import_images(
    folder: Path = typer.Argument(..., help="Folder of images (png, jpg, bmp, tif…), one per robot state."),
    target: str = typer.Option(..., "--target", help="chessboard:COLSxROWS:SQUARE_M (inner corners) | "
                               "charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT | aprilgrid:COLSxROWS:TAG_M:SPACING_RATIO[:DICT]."),
    out: Path = typer.Option(..., "--out", help="Recording to write (MCAP)."),
    poses: Path = typer.Option(None, "--poses", help="The flange pose in the robot base frame at each image: a CSV "
                               "(image, x, y, z m, qx, qy, qz, qw or roll, pitch, yaw rad), or a text file of "
                               "row-major 4×4 base→flange matrices, one per line, line N ↔ the image numbered N."),
    joints: Path = typer.Option(None, "--joints", help="CSV: image and one column per joint of the chain."),
    urdf: Path = typer.Option(None, "--urdf", help="Robot description (with --joints)."),
    root: str = typer.Option("", "--root", help="Root link of the chain (with --joints)."),
    tip: str = typer.Option("", "--tip", help="Tip link of the chain, where the camera or board is (with --joints)."),
    joint_units: Literal["rad", "deg"] = typer.Option("rad", "--joint-units", help="Revolute joint columns in rad or deg."),
    camera_on: Literal["tip", "world"] = typer.Option("tip", "--camera-on", help="tip (eye-in-hand; board fixed) or world "
                                  "(eye-to-hand; board on the tip)."),
    lens: Literal["pinhole", "fisheye"] = typer.Option("pinhole", "--lens", help="pinhole (OpenCV k1..k6, p1, p2) or fisheye (equidistant)."),
    n_dist: int = typer.Option(0, "--distortion-terms", help="Pinhole: 4, 5 or 8 terms fitted at most "
                               "(default 8: k3 and k4–k6 only where held-out error supports them); fisheye: 4."),
    max_edge_px: float = typer.Option(5.0, "--max-edge-px", help="A chessboard with edges wider than this (px) is blurred."),
    keep_images: bool = typer.Option(False, "--keep-images", help="Store each used image in the recording (attachment)."),
    workers: int = typer.Option(0, "--workers", min=0, help="Detection processes (0: the CPU count)."),
    only: str = typer.Option("", "--only", help="Import only these images: comma-separated names, stems or shell "
                             "patterns (im_05,im_14)."),
    exclude: str = typer.Option("", "--exclude", help="Leave these images out (names, stems or patterns), e.g. a "
                                "held-out set for `robocal evaluate`."),
    skip_bad: bool = typer.Option(False, "--skip-bad", help="Leave out unreadable images, images of another size "
                                  "and images without a row in the CSV (listed) instead of failing."),
    force: bool = force_option(),
) -> None:
    """Detect the target in every image, pair each with the robot's state, write a recording `robocal run` calibrates."""
    from pipeline.camera.detect import detect_folder, image_files
    from pipeline.camera.targets import parse
    from pipeline.errors import RobocalError
    from pipeline.importers import images as im
    from pipeline.importers import pose_files
    from pipeline.models import urdf as urdf_mod
    from pipeline.recording.output import check_output, claim_output

    check_output(out, force=force)  # before any work: an existing recording only with --force
    if (poses is None) == (joints is None):
        raise RobocalError("give the robot's state at each image with exactly one of --poses or --joints")
    if camera_on not in ("tip", "world"):
        raise RobocalError(f"--camera-on {camera_on!r}: expected tip or world")
    if joint_units not in ("rad", "deg"):
        raise RobocalError(f"--joint-units {joint_units!r}: expected rad or deg")
    if lens not in ("pinhole", "fisheye"):
        raise RobocalError(f"--lens {lens!r}: expected pinhole or fisheye")
    n_dist = n_dist or (8 if lens == "pinhole" else 4)
    if n_dist not in ((4, 5, 8) if lens == "pinhole" else (4,)):
        raise RobocalError(f"--distortion-terms {n_dist}: {lens} takes {'4, 5 or 8' if lens == 'pinhole' else '4'}")
    tgt = parse(target)
    if not folder.is_dir():
        raise RobocalError(f"{folder}: not a folder of images")
    files = image_files(folder)
    if not files:
        raise RobocalError(f"{folder}: no image files (png, jpg, bmp, tif, pgm, ppm, webp)")
    im_files = im.select(files, only, exclude)
    if not im_files:
        raise RobocalError(f"{folder}: --only / --exclude leave no image of {len(files)}")
    if joints is not None:
        if urdf is None or not root or not tip:
            raise RobocalError("--joints needs --urdf, --root and --tip")
        desc = urdf_mod.read(urdf, root, tip)
        states = pose_files.read_joints(joints, desc, joint_units)
    else:
        desc = im.pose_chain()
        states = pose_files.read_poses(poses)

    def progress(done: int, total: int) -> None:
        if done == total or done % 10 == 0:
            err.print(f"detected {done}/{total} images", highlight=False, soft_wrap=True)

    dets = im.match(detect_folder(im_files, tgt, max_edge_px, workers or None, progress), states,
                    [f.name for f in files])
    for d in dets:
        if d.status != "ok":
            err.print(f"[yellow]{d.name}:[/] {d.status}: {d.reason}" + ("" if d.used else " — not used"),
                      highlight=False, soft_wrap=True)
    used = [d for d in dets if d.used]
    bad = [d for d in dets if d.status in BAD]
    if bad and not skip_bad:
        names = ", ".join(d.name for d in bad[:5]) + (" …" if len(bad) > 5 else "")
        ok = ", ".join(d.name for d in used[:8]) + (" …" if len(used) > 8 else "")
        raise RobocalError(f"{folder / bad[0].name}: {bad[0].status}: {bad[0].reason} ({len(bad)} bad image(s): {names}); "
                           f"usable: {len(used)} of {len(dets)} images ({ok or 'none'}); --skip-bad leaves the bad ones out")
    if len(used) < 3:
        listed = "; ".join(f"{d.name}: {d.status}" for d in dets[:6]) + (" …" if len(dets) > 6 else "")
        raise RobocalError(f"{folder}: the target {tgt.spec} was usable in {len(used)} of {len(dets)} images "
                           f"(a calibration needs at least 3): {listed}")
    size = used[0].size
    campaign = {"mount": camera_on, "lens": lens, "n_dist": n_dist, "image_size": list(size),
                "kinematics_known": poses is not None, "source_files": [str(folder), str(states.path)],
                "robot_id": desc.name}
    claim_output(out, force=force)  # with --force the old recording kept as NAME.bak
    n = im.write_camera_recording(out, desc, tgt, dets, campaign, folder, keep_images)
    err.print(f"states: {states.rule()}", highlight=False, soft_wrap=True)
    err.print(f"imported {n} of {len(dets)} images ({sum(len(d.ids) for d in used)} corners, {size[0]}x{size[1]} px, "
              f"camera on the {camera_on}) into {out}", highlight=False, soft_wrap=True)
