"""ROS 2 bags → the encoder stream of a dynamics recording: every ``sensor_msgs/msg/JointState`` of the joint
topic with its positions, velocities and efforts (rosbags reads and decodes; the chain's joints matched by
name, any order, other joints ignored).  Times are the messages' ``header.stamp`` (or the receive times with
``time="log"``).  Refused with one line naming the file, topic and record: a message without an effort per
name, NaN or inf, times that do not increase."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError
from pipeline.ros2.bag import Bag
from pipeline.ros2.points import JOINT_STATE, _decoder, _Rows, _stamp, at, choose_joint_topic
from pipeline.models.urdf import RobotDescription


def read_effort_bag(path: Path, urdf: Path | None, root: str, tip: str, joint_topic: str = "/joint_states",
                    time: str = "header") -> tuple[RobotDescription, str, dict[str, np.ndarray]]:
    """(the chain `root` → `tip` of the URDF (a file, a .xacro, or None: the bag's /robot_description), where
    it came from, {t_ns (T,), q (T, J), v (T, J) or absent, effort (T, J)} in the chain's joint order); the
    bag opened once."""
    from pipeline.models import urdf as urdf_mod
    from pipeline.ros2.importer import urdf_text

    path = Path(path)
    bag = Bag(path)
    try:
        text, source = urdf_text(bag, urdf)
        desc = urdf_mod.parse(text, root, tip, source=source)
        joints = desc.joint_names
        topics = bag.topics
        jt = choose_joint_topic(path, topics, joint_topic)
        decode = _decoder(path, jt, JOINT_STATE)
        Q, V, E, T = _Rows(len(joints)), _Rows(len(joints)), _Rows(len(joints)), _Rows(1, np.int64)
        prev, idx, velocities, rec = None, None, True, []
        for i, (log_t, data) in enumerate((t, d) for _, t, d in bag.messages([jt])):
            msg = decode(i, data)
            if msg.name != prev:
                prev = list(msg.name)
                pos_of = {nm: k for k, nm in enumerate(prev)}
                missing = [j for j in joints if j not in pos_of]
                if missing:
                    raise RobocalError(f"{at(path, jt, i)}: chain joint(s) {', '.join(missing)} missing from the "
                                       f"JointState names ({', '.join(prev)})")
                idx = np.array([pos_of[j] for j in joints], np.intp)
            n = len(prev)
            if len(msg.position) != n or len(msg.effort) != n:
                raise RobocalError(f"{at(path, jt, i)}: {len(msg.position)} positions and {len(msg.effort)} efforts "
                                   f"for {n} joint names: a dynamics recording needs an effort per joint")
            Q.append(np.asarray(msg.position, float)[idx])
            E.append(np.asarray(msg.effort, float)[idx])
            if len(msg.velocity) == n:
                V.append(np.asarray(msg.velocity, float)[idx])
            else:
                velocities = False
            T.append((_stamp(msg) if time == "header" and _stamp(msg) > 0 else log_t,))
            rec.append(i)
    finally:
        bag.close()
    if not rec:
        raise RobocalError(f"{at(path, jt)}: no messages")
    out = {"t_ns": T.array()[:, 0], "q": Q.array(), "effort": E.array()}
    if velocities:
        out["v"] = V.array()
    for key in ("q", "v", "effort"):
        if key in out and (bad := np.argwhere(~np.isfinite(out[key]))).size:
            r, k = bad[0]
            raise RobocalError(f"{at(path, jt, rec[r])}: joint {joints[k]!r} {key} is NaN or inf")
    back = np.flatnonzero(np.diff(out["t_ns"]) <= 0)
    if back.size:
        raise RobocalError(f"{at(path, jt, rec[back[0] + 1])}: time does not increase after the previous record "
                           "(a dynamics recording needs strictly increasing times)")
    return desc, source, out
