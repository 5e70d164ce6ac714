"""The camera side of `robocal import ros2` (with ``--target``): read the bag, say what was paired,
excluded and detected, then write the recording — or one line and exit 2 for bad input, the usable
images listed.  Registers no command."""

from __future__ import annotations

from pathlib import Path

from pipeline.cli import err


def _say(line: str) -> None:
    err.print(line, highlight=False, soft_wrap=True)


def _print_pairing(bag: Path, extras: dict) -> None:
    for w in extras.get("import_warnings", []):
        _say(f"[yellow]warning:[/] {w}")
    r = extras["ros2"]
    p, js, c = r["pairing"], r["joint_states"], r["clock_offset"]
    _say(f"{bag}: {js['n_used']} joint states on {r['joint_topic']}, {p['n_measurements']} images on "
         f"{r['image_topic']} ({r['image_type']}), CameraInfo on {r['camera_info_topic'] or 'none'}")
    _say(f"standstill pairing (window {p['standstill_window_s']:g} s ± clock-offset bound {c['bound_s']:g} s, max speed "
         f"{p['max_speed_rad_s_or_m_s'] * p['window_s'] / p['standstill_window_s']:g} rad/s): {p['n_paired']} paired, "
         f"{p['n_moving']} taken while moving, {p['n_not_covered']} outside the joint states — excluded")
    cons = c.get("consistent_s")
    line = "clock offset (camera − joints): "
    line += (f"every paired image stands still for offsets {cons[0]:+.2f} … {cons[1]:+.2f} s" if cons else
             "no offset keeps every paired image still")
    if c.get("estimate_s") is not None:
        line += f", estimate {c['estimate_s']:+.2f} s if they were taken mid-stop"
    _say(line + (f" (applied offset {c['applied_offset_s']:+g} s)" if c["applied_offset_s"] else ""))
    for e in p["moving"]:
        _say(f"[yellow]excluded:[/] {r['image_topic']} record {e['index']} at {e['t_s']:.3f} s: moving "
             f"({e['joint']} {e['speed']:.3g} rad/s over the window)")
    for e in p["not_covered"]:
        _say(f"[yellow]excluded:[/] {r['image_topic']} record {e['index']} at {e['t_s']:.3f} s: no joint states around it")


def import_camera(bag: Path, urdf: Path, root: str, tip: str, out: Path, spec, cam, robot_id: str = "",
                  force: bool = False) -> None:
    """`robocal import ros2 BAG --target …`: detections of the paired images → a camera recording (an
    existing recording at `out` replaced only with `force`, kept as NAME.bak)."""
    from pipeline.errors import RobocalError
    from pipeline.importers.images import write_camera_recording
    from pipeline.importers.ros2_camera import BAD, read_camera_bag
    from pipeline.importers.ros2_images import DISTORTION_MODELS, start_intrinsics
    from pipeline.camera.targets import parse
    from pipeline.models import urdf as urdf_mod

    if cam.mount not in ("tip", "world"):
        raise RobocalError(f"--camera-on {cam.mount!r}: expected tip or world")
    if cam.lens not in ("pinhole", "fisheye"):
        raise RobocalError(f"--lens {cam.lens!r}: expected pinhole or fisheye")
    if cam.n_dist not in ((4, 5, 8) if cam.lens == "pinhole" else (4,)):
        raise RobocalError(f"--distortion-terms {cam.n_dist}: {cam.lens} takes {'4, 5 or 8' if cam.lens == 'pinhole' else '4'}")
    if out.exists() and out.resolve() == bag.resolve():
        raise RobocalError(f"{out}: --out is the bag itself")
    tgt = parse(cam.target)
    desc = urdf_mod.read(urdf, root, tip)

    def progress(done: int, total: int) -> None:
        if done == total or done % 10 == 0:
            _say(f"detected {done}/{total} images")

    dets, extras, problems, info = read_camera_bag(bag, desc.joint_names, spec, cam, progress,
                                                   on_paired=lambda ex: _print_pairing(bag, ex))
    for d in dets:
        if d.status != "ok":
            _say(f"[yellow]{d.name}:[/] {d.status}: {d.reason}" + ("" if d.used else " — not used"))
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
        raise RobocalError(f"{bag}: topic {extras['ros2']['image_topic']}: none of the {pr['n_measurements']} images was "
                           f"taken while the robot stood still ({pr['n_moving']} moving, {pr['n_not_covered']} outside "
                           f"the joint states; window {pr['standstill_window_s']:g} s ± clock-offset bound "
                           f"{extras['ros2']['clock_offset']['bound_s']:g} s; see --clock-offset, --clock-offset-bound, "
                           "--still-window, --still-speed)")
    if len(used) < 3:
        listed = "; ".join(f"{d.name}: {d.status}" for d in dets[:6]) + (" …" if len(dets) > 6 else "")
        raise RobocalError(f"{bag}: the target {tgt.spec} was usable in {len(used)} of {len(dets)} paired images "
                           f"(a calibration needs at least 3){': ' + listed if listed else ''}")
    k0 = start_intrinsics(info, cam.lens, cam.n_dist)
    model = DISTORTION_MODELS.get(info.distortion_model, ("", 0))[0]
    if k0 is not None and model != cam.lens:
        _say(f"[yellow]warning:[/] CameraInfo distortion model {info.distortion_model!r} is not the {cam.lens} lens: "
             "its K is the start, its D is not")
    campaign = {"mount": cam.mount, "lens": cam.lens, "n_dist": cam.n_dist, "image_size": list(info.size),
                "kinematics_known": cam.kinematics_known, "robot_id": robot_id or desc.name, **extras}
    if k0 is not None:
        campaign["start_intrinsics"] = k0
    from pipeline.recording.output import claim_output

    claim_output(out, force=force)  # with --force the old recording kept as NAME.bak
    n = write_camera_recording(out, desc, tgt, dets, campaign)
    _say(f"imported {n} of {len(dets)} paired images ({sum(len(d.ids) for d in used)} corners, "
         f"{info.width}x{info.height} px, camera on the {cam.mount}) into {out}")
