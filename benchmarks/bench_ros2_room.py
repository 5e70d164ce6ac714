"""Benchmark: how often one ROS 2 import opens the bag, decodes its messages, enters the ROS 2 code and
calls back up into the command line.

Run: .venv/bin/python benchmarks/bench_ros2_room.py
Two bags written by rosbags' own Writer: a point bag (a 6R robot, 12 stops, PointStamped) imported with
`robocal import ros2`, and a camera bag (16 stops, mono8 Image + CameraInfo) walked through
`robocal run BAG --target …` up to the end of its import (the stages after it are not run; one worker,
so every decode happens in this process).  Counted in-process, the command line called as the user
calls it:

- opens: the bag's files opened (Python's ``open`` audit event on any path inside the bag) and rosbags
  ``Reader.open`` calls;
- decodes: rosbags ``deserialize_cdr`` calls, per message type, against the messages of that type the
  bag holds (1.0 = each decoded once);
- entries: calls into the ROS 2 code (``pipeline/ros2/`` or, before it, ``pipeline/importers/ros2*``,
  ``bag_import``, ``bagkind``) from code outside it; climbs: calls into ``pipeline/cli/`` from the
  pipeline's code outside the command line (the import calling the CLI back).
"""

from __future__ import annotations

import re
import sys
import tempfile
import threading
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

ROOM = re.compile(r"pipeline/(ros2/|importers/(ros2[a-z_]*|bag_import|bagkind)\.py)")
CLI = re.compile(r"pipeline/cli/")
PIPE = re.compile(r"/pipeline/")


class Stop(Exception):
    """Raised where `robocal run` would start its stages: the import is done."""


def _count(argv: list[str], bag: Path) -> dict:
    from rosbags.rosbag2 import Reader
    from rosbags.typesys.store import Typestore

    from pipeline.cli import app, load_commands

    c: dict = {"opens": 0, "reader_open": 0, "decodes": Counter(), "entries": 0, "climbs": 0, "entered": Counter(),
               "climbed": Counter()}
    bag_s = str(bag.resolve())
    watching = [True]

    def audit(event, args):
        if watching[0] and event == "open" and isinstance(args[0], (str, bytes, Path)):
            p = str(Path(args[0]).resolve()) if not isinstance(args[0], bytes) else args[0].decode()
            if p.startswith(bag_s):
                c["opens"] += 1

    def profile(frame, event, arg):
        if event != "call":
            return
        callee = frame.f_code.co_filename
        caller = frame.f_back.f_code.co_filename if frame.f_back else ""
        if ROOM.search(callee) and not ROOM.search(caller) and PIPE.search(caller):
            c["entries"] += 1
            c["entered"][f"{Path(callee).stem}.{frame.f_code.co_name}"] += 1
        if CLI.search(callee) and PIPE.search(caller) and not CLI.search(caller):
            c["climbs"] += 1
            c["climbed"][f"{Path(callee).stem}.{frame.f_code.co_name}"] += 1

    open0, deser0 = Reader.open, Typestore.deserialize_cdr

    def reader_open(self, *a, **k):
        c["reader_open"] += 1
        return open0(self, *a, **k)

    def deserialize(self, rawdata, typename, *a, **k):
        c["decodes"][typename] += 1
        return deser0(self, rawdata, typename, *a, **k)

    import pipeline.stages.runner as runner

    def stop(*a, **k):
        raise Stop

    run0 = runner.run_pipeline
    Reader.open, Typestore.deserialize_cdr, runner.run_pipeline = reader_open, deserialize, stop
    sys.addaudithook(audit)
    load_commands(argv)
    sys.setprofile(profile)
    threading.setprofile(profile)
    try:
        app(argv, standalone_mode=False)
    except Stop:
        pass
    finally:
        sys.setprofile(None)
        threading.setprofile(None)
        watching[0] = False
        Reader.open, Typestore.deserialize_cdr, runner.run_pipeline = open0, deser0, run0
    return c


def _held(bag: Path) -> Counter:
    """Messages of each type the bag holds (read with rosbags, outside the counting)."""
    from rosbags.rosbag2 import Reader

    with Reader(bag) as r:
        return Counter({c.msgtype: c.msgcount for c in r.connections})


def _show(name: str, c: dict, held: Counter) -> None:
    print(f"\n{name}")
    print(f"  bag files opened: {c['opens']}   rosbags Reader.open: {c['reader_open']}")
    for ty, n in sorted(held.items()):
        d = c["decodes"].get(ty, 0)
        print(f"  {ty}: {n} messages, {d} decodes ({d / n:.2f} per message)")
    print(f"  entries into the ROS 2 code from outside it: {c['entries']}   calls back up into the CLI: {c['climbs']}")
    for k, v in c["entered"].most_common():
        print(f"    {v:3d} × {k}  (entry)")
    for k, v in c["climbed"].most_common():
        print(f"    {v:3d} × {k}  (CLI code called from the pipeline)")


def main() -> None:
    import os

    from r6_robot import BARE_URDF

    from pipeline.models import urdf
    from pipeline.simulate.ros2_bag import BagLayout, simulate_bag

    os.cpu_count = lambda: 1  # one detection worker: every decode in this process
    tmp = Path(tempfile.mkdtemp(prefix="bench_ros2_room_"))
    (tmp / "r6.urdf").write_text(BARE_URDF)
    desc = urdf.parse(BARE_URDF, "b", "l6")
    simulate_bag(tmp / "point", desc, "point", n=12, seed=1, layout=BagLayout(rate_hz=50.0))
    c = _count(["import", "ros2", str(tmp / "point"), "--urdf", str(tmp / "r6.urdf"), "--root", "b", "--tip", "l6",
                "--out", str(tmp / "point.mcap")], tmp / "point")
    _show("point bag: robocal import ros2", c, _held(tmp / "point"))

    from test_ros2_camera_import import INFO_K, OFFSET_S, Q_HOME, TARGET, _truth

    from pipeline.simulate import camera_images as ci
    from pipeline.simulate.ros2_camera_bag import CameraBagLayout, write_camera_bag

    model, tgt, rng, x = _truth()
    q = ci.poses(model, x, Q_HOME, 16, tgt, rng)
    write_camera_bag(tmp / "cam", model, x, q, tgt, rng, CameraBagLayout(dwell_s=3.0, clock_offset_s=OFFSET_S,
                                                                         moving=(4, 11), info_k=INFO_K[:9]))
    c = _count(["run", str(tmp / "cam"), "--urdf", str(tmp / "r6.urdf"), "--root", "b", "--tip", "l6", "--target",
                TARGET, "--clock-offset-bound-s", "0.4", "--out", str(tmp / "run")], tmp / "cam")
    _show("camera bag: robocal run BAG --target … (up to the end of the import)", c, _held(tmp / "cam"))
    print(f"\n(bags in {tmp})")
    np.random.seed(0)


if __name__ == "__main__":
    main()
