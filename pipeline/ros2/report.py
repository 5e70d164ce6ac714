"""What a ROS 2 import says while it works, as plain lines handed to the caller's `say` (the command line
colours the words ``warning:`` and ``excluded:`` and prints them; nothing here prints): the topics read,
the standstill pairing and every record left out, the clock offsets of a camera bag, what was written."""

from __future__ import annotations

from pathlib import Path
from typing import Callable

Say = Callable[[str], None]


def quiet(line: str) -> None:
    """A `say` that says nothing."""


def read_lines(bag: Path, extras: dict, say: Say) -> None:
    """What a point / pose import read: its warnings, the topics and the standstill pairing, every excluded record."""
    for w in extras.get("import_warnings", []):
        say(f"warning: {w}")
    r = extras["ros2"]
    p = r["pairing"]
    js = r["joint_states"]
    if js.get("efforts_dropped"):
        say(f"warning: {js['efforts_dropped']}")
    skipped = f", {js['n_skipped_other_joints']} naming only other joints skipped" if js["n_skipped_other_joints"] else ""
    say(f"{bag}: {js['n_used']} joint states on {r['joint_topic']} (ignored joints: "
        f"{', '.join(js['ignored_joints']) or 'none'}{skipped}), {p['n_measurements']} measurements on "
        f"{r['measure_topic']} in frame {r['frame_id']!r}")
    say(f"standstill pairing (window {p['window_s']:g} s, max speed {p['max_speed_rad_s_or_m_s']:g} rad/s): "
        f"{p['n_paired']} paired, {p['n_moving']} taken while moving, {p['n_not_covered']} outside the joint "
        "states — excluded")
    _excluded(p, r["measure_topic"], say)


def _excluded(p: dict, topic: str, say: Say) -> None:
    for e in p["moving"]:
        say(f"excluded: {topic} record {e['index']} at {e['t_s']:.3f} s: moving ({e['joint']} {e['speed']:.3g} rad/s "
            "over the window)")
    for e in p["not_covered"]:
        say(f"excluded: {topic} record {e['index']} at {e['t_s']:.3f} s: no joint states around it")
    listed = len(p["moving"]) + len(p["not_covered"])
    if listed < p["n_moving"] + p["n_not_covered"]:
        say(f"… and {p['n_moving'] + p['n_not_covered'] - listed} more excluded (all counted in the recording's "
            "campaign metadata)")


def written_lines(done, say: Say) -> None:
    """What a point / pose import wrote (a `pipeline.ros2.importer.BagImport`)."""
    if done.n_stream is not None:
        say(f"kept the efforts of {done.n_stream} joint states in the encoder stream")
    say(f"imported {done.n} {done.kind} measurements of {done.n_joints} joints ({done.root} → {done.tip}) into "
        f"{done.out}")


def pairing_lines(bag: Path, extras: dict, say: Say) -> None:
    """What a camera import read and paired, and the clock offsets the stillness allows."""
    for w in extras.get("import_warnings", []):
        say(f"warning: {w}")
    r = extras["ros2"]
    p, js, c = r["pairing"], r["joint_states"], r["clock_offset"]
    say(f"{bag}: {js['n_used']} joint states on {r['joint_topic']}, {p['n_measurements']} images on "
        f"{r['image_topic']} ({r['image_type']}), CameraInfo on {r['camera_info_topic'] or 'none'}")
    say(f"standstill pairing (window {p['standstill_window_s']:g} s ± clock-offset bound {c['bound_s']:g} s, max speed "
        f"{p['max_speed_rad_s_or_m_s'] * p['window_s'] / p['standstill_window_s']:g} rad/s): {p['n_paired']} paired, "
        f"{p['n_moving']} taken while moving, {p['n_not_covered']} outside the joint states — excluded")
    cons = c.get("consistent_s")
    line = "clock offset (camera − joints): "
    line += (f"every paired image stands still for offsets {cons[0]:+.2f} … {cons[1]:+.2f} s" if cons else
             "no offset keeps every paired image still")
    if c.get("estimate_s") is not None:
        line += f", estimate {c['estimate_s']:+.2f} s if they were taken mid-stop"
    say(line + (f" (applied offset {c['applied_offset_s']:+g} s)" if c["applied_offset_s"] else ""))
    _excluded(p, r["image_topic"], say)
