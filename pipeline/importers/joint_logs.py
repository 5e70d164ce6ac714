"""What a joint log (joint angles over time, rad / m, in a chain's joint order) may be, whatever it was read
from (`import csv --measure effort`, a ROS 2 bag's JointStates): positions within the URDF's limits (widened
by `bounds.LIMIT_SLACK` of the range, the bound every importer applies) and speeds within its velocity limits
(`SPEED_SLACK` ×).  A log beyond either is a unit or clock mistake (degrees, motor-side angles, a wrong
rate), refused with one line; `where(i)` names sample i in the caller's words (``file: row 12``, ``bag: topic
/joint_states: record 12``).  Vectorised over samples."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Callable

import numpy as np

from pipeline.errors import RobocalError
from pipeline.importers.bounds import LIMIT_SLACK
from pipeline.models.urdf import RobotDescription

SPEED_SLACK = 3.0  # a joint moving faster than this many times its URDF velocity limit: a clock or scale mistake


def check_limits(where: Callable[[int], str], q: np.ndarray, desc: RobotDescription, converted: bool = False) -> None:
    """One line for a position of `q` (T, J) far outside its joint's URDF limits (beyond `LIMIT_SLACK` of the
    range: a unit mistake, motor-side angles, or a trajectory the robot cannot have run); `converted`: the
    readings went through a --position-* conversion."""
    joints = desc.movable
    lo, hi = np.array([j.lower for j in joints]), np.array([j.upper for j in joints])
    finite = np.isfinite(hi - lo)
    slack = np.where(finite, LIMIT_SLACK * np.where(finite, hi - lo, 0.0), np.inf)
    out_of = (q < lo - slack) | (q > hi + slack)
    if out_of.any():
        i, k = np.argwhere(out_of)[0]
        hint = ("after the --position-scale / --position-mix / --position-offset conversion" if converted else
                "(motor-side angles? --position-scale JOINT=1/RATIO; degrees? --position-scale JOINT=pi/180)")
        raise RobocalError(f"{where(int(i))}: joint {joints[k].name!r}: position {q[i, k]:.6g} is far outside the "
                           f"URDF's limits [{lo[k]:.6g}, {hi[k]:.6g}] {hint}")


def check_speeds(where: Callable[[int], str], t: np.ndarray, q: np.ndarray, desc: RobotDescription) -> None:
    """One line when a joint of `q` (T, J) at times `t` (T,) s moves far faster than its URDF's ``<limit
    velocity>`` (beyond `SPEED_SLACK` ×): a wrong rate or time column, or a position scale too large.  Speeds
    over 10 ms steps (encoder noise averaged).  A clock or scale mistake is systematic, so it is the 99th
    percentile of a joint's speed that is judged: one encoder glitch does not refuse a log.  Joints without a
    velocity limit, and continuous joints (whose logged angle may wrap at ±π), are not checked."""
    if len(t) < 3:
        return
    limit = {}
    for j in ET.fromstring(desc.urdf).iter("joint"):
        lim = j.find("limit")
        try:
            limit[j.get("name")] = (float(lim.get("velocity")) if lim is not None and j.get("type") != "continuous"
                                    else 0.0)
        except (TypeError, ValueError):
            limit[j.get("name")] = 0.0
    vmax = np.array([limit.get(j.name, 0.0) for j in desc.movable])
    dt = float(np.median(np.diff(t)))
    k = max(1, int(round(0.01 / dt))) if dt > 0 else 1
    k = min(k, len(t) - 1)
    speed = np.abs(q[k:] - q[:-k]) / (t[k:] - t[:-k])[:, None]
    over = (vmax > 0) & (np.percentile(speed, 99, axis=0) > SPEED_SLACK * vmax)
    if over.any():
        c = int(np.argmax(over))
        i = int(np.argmax(speed[:, c]))
        raise RobocalError(f"{where(i)}: joint {desc.movable[c].name!r} moves at {speed[i, c]:.4g} /s, "
                           f"{speed[i, c] / vmax[c]:.0f}× its URDF velocity limit {vmax[c]:.4g} (a wrong --rate or "
                           "time column, or --position-scale?)")
