"""ROS 2 bags → the encoder stream of a dynamics recording: every ``sensor_msgs/msg/JointState`` of the joint
topic with its positions, velocities and efforts (rosbags reads and decodes; the chain's joints matched by
name, any order, other joints ignored).  Times are the messages' ``header.stamp`` (or the receive times with
``time="log"``).  Positions that are not joint angles (a driver publishing motor-side angles) are converted
by the declaration `positions` (`pipeline.importers.joint_readings`).  Refused with one line naming the file,
topic and record: a message without an effort per name, NaN or inf, times that do not increase, positions or
speeds beyond the URDF's limits (`pipeline.importers.joint_logs`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError
from pipeline.ros2.bag import Bag
from pipeline.models.urdf import RobotDescription
from pipeline.ros2.points import JOINT_STATE, _decoder, _Rows, _stamp, at, choose_joint_topic


def read_efforts(bag: Bag, desc: RobotDescription, joint_topic: str = "/joint_states",
                 time: str = "header", positions: dict | None = None) -> dict[str, np.ndarray]:
    """{t_ns (T,), q (T, J) rad / m, v (T, J) or absent, effort (T, J) raw} of the open `bag`'s joint topic in the
    chain `desc`'s joint order, each message decoded once; `positions`: the readings' conversion to joint
    angles (`joint_readings.declaration`; None: they are joint angles)."""
    from pipeline.importers import joint_logs, joint_readings

    path = Path(bag.path)
    joints = desc.joint_names
    jt = choose_joint_topic(path, bag.topics, joint_topic)
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
    out["q"], v = joint_readings.convert(positions, joints, out["q"], out.get("v"))
    if v is not None:
        out["v"] = v
    where = lambda i: at(path, jt, rec[i])  # noqa: E731
    joint_logs.check_limits(where, out["q"], desc, converted=bool(positions))
    joint_logs.check_speeds(where, out["t_ns"] * 1e-9, out["q"], desc)
    return out
