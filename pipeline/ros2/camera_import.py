"""The camera side of a ROS 2 import (``--target``): the paired images' detections checked (one line and exit 2
for bad input, the usable images listed) and written as a camera recording; what was paired, excluded and
detected said through `say` on the way (`pipeline.ros2.report`)."""

from __future__ import annotations

from pathlib import Path

from pipeline.ros2.report import Say, pairing_lines


def check_camera(cam) -> None:
    """The camera declaration's words checked before the bag is read."""
    from pipeline.errors import RobocalError

    if cam.mount not in ("tip", "world"):
        raise RobocalError(f"--camera-on {cam.mount!r}: expected tip or world")
    if cam.lens not in ("pinhole", "fisheye"):
        raise RobocalError(f"--lens {cam.lens!r}: expected pinhole or fisheye")
    if cam.n_dist not in ((4, 5, 8) if cam.lens == "pinhole" else (4,)):
        raise RobocalError(f"--distortion-terms {cam.n_dist}: {cam.lens} takes {'4, 5 or 8' if cam.lens == 'pinhole' else '4'}")


def import_camera(bag, desc, out: Path, spec, cam, robot_id: str = "", force: bool = False,
                  say: Say = print) -> int:
    """Detections of the paired images of the open `bag` (`pipeline.ros2.bag.Bag`; the robot `desc`) → a
    camera recording at `out` (an existing recording replaced only with `force`, kept as NAME.bak); returns
    the images written."""
    from pipeline.camera.targets import parse
    from pipeline.errors import RobocalError
    from pipeline.importers.images import write_camera_recording
    from pipeline.ros2.camera import BAD, read_camera_bag
    from pipeline.ros2.images import DISTORTION_MODELS, start_intrinsics

    tgt = parse(cam.target)
    path = bag.path

    def progress(done: int, total: int) -> None:
        if done == total or done % 10 == 0:
            say(f"detected {done}/{total} images")

    dets, extras, problems, info = read_camera_bag(bag, desc.joint_names, spec, cam, progress,
                                                   on_paired=lambda ex: pairing_lines(path, ex, say))
    for d in dets:
        if d.status != "ok":
            say(f"warning: {d.name}: {d.status}: {d.reason}" + ("" if d.used else " — not used"))
    used = [d for d in dets if d.used]
    ok = ", ".join(d.name for d in used[:6]) + (" …" if len(used) > 6 else "")
    usable = f"usable: {len(used)} of {len(dets)} paired images ({ok or 'none'})"
    bad = [d for d in dets if d.status in BAD]
    fatal = [p for p in problems if not (cam.skip_bad and any(p.endswith(f"{d.status}: {d.reason}") for d in bad))]
    if fatal:
        more = f" (+{len(problems) - 1} more problem(s))" if len(problems) > 1 else ""
        hint = "; --skip-bad leaves the bad images out" if bad and len(fatal) == len(bad) else ""
        raise RobocalError(f"{fatal[0]}{more}; {usable}{hint}")
    pr = extras["ros2"]["pairing"]
    if not dets:
        raise RobocalError(f"{path}: topic {extras['ros2']['image_topic']}: none of the {pr['n_measurements']} images was "
                           f"taken while the robot stood still ({pr['n_moving']} moving, {pr['n_not_covered']} outside "
                           f"the joint states; window {pr['standstill_window_s']:g} s ± clock-offset bound "
                           f"{extras['ros2']['clock_offset']['bound_s']:g} s; see --clock-offset-s, --clock-offset-bound-s, "
                           "--still-window-s, --still-speed-rad-s)")
    if len(used) < 3:
        listed = "; ".join(f"{d.name}: {d.status}" for d in dets[:6]) + (" …" if len(dets) > 6 else "")
        raise RobocalError(f"{path}: the target {tgt.spec} was usable in {len(used)} of {len(dets)} paired images "
                           f"(a calibration needs at least 3){': ' + listed if listed else ''}")
    k0 = start_intrinsics(info, cam.lens, cam.n_dist)
    model = DISTORTION_MODELS.get(info.distortion_model, ("", 0))[0]
    if k0 is not None and model != cam.lens:
        say(f"warning: CameraInfo distortion model {info.distortion_model!r} is not the {cam.lens} lens: "
             "its K is the start, its D is not")
    campaign = {"mount": cam.mount, "lens": cam.lens, "n_dist": cam.n_dist, "image_size": list(info.size),
                "kinematics_known": cam.kinematics_known, "robot_id": robot_id or desc.name, **extras}
    if k0 is not None:
        campaign["start_intrinsics"] = k0
    from pipeline.recording.output import claim_output

    claim_output(out, force=force)  # with --force the old recording kept as NAME.bak
    n = write_camera_recording(out, desc, tgt, dets, campaign)
    say(f"imported {n} of {len(dets)} paired images ({sum(len(d.ids) for d in used)} corners, "
         f"{info.width}x{info.height} px, camera on the {cam.mount}) into {out}")
    return n
