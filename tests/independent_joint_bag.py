"""A ROS 2 bag of a robot that approaches each posture from a chosen side, written by rosbags' own writer.

Shares NO code with robocal: the joint stream is built here (numpy) and serialised by rosbags.  For
posture i (joint readings q_i, rad, and directions d_i = ±1 per joint) the robot moves in straight
joint-space lines, `RATE_HZ` JointState samples a second: from q_{i−1} to the pre-posture
q_i − d_i·`OVERSHOOT_RAD` (`MOVE_S`), from there to q_i (`MOVE_S`; each joint's last motion is then
towards d_i), and holds still for `HOLD_S`; the markers (PointStamped, one topic per measured link,
frame ``mocap``) are stamped at the middle of the hold.  Header stamps and receive times are equal.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

T0_NS = 1_700_000_000_000_000_000
RATE_HZ = 50.0
MOVE_S = 0.6
HOLD_S = 1.0
OVERSHOOT_RAD = 0.03


def stream(q: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(sample times ns (T,), positions (T, J) rad, measurement times ns (n,)) of the motion above."""
    q, d = np.asarray(q, float), np.asarray(d, float)
    dt = 1.0 / RATE_HZ
    k_move, k_hold = int(round(MOVE_S * RATE_HZ)), int(round(HOLD_S * RATE_HZ))
    s = np.arange(1, k_move + 1)[:, None] / k_move  # (k, 1) fraction of a move, ending at its goal
    ts, qs, tm = [], [], []
    prev, t = q[0] - d[0] * OVERSHOOT_RAD, 0.0
    for i in range(len(q)):
        pre = q[i] - d[i] * OVERSHOOT_RAD
        seg = np.vstack([prev + s * (pre - prev), pre + s * (q[i] - pre), np.repeat(q[i][None], k_hold, 0)])
        ts.append(t + dt * np.arange(1, len(seg) + 1))
        qs.append(seg)
        tm.append(t + dt * (2 * k_move) + HOLD_S / 2)
        t = ts[-1][-1]
        prev = q[i]
    to_ns = lambda x: T0_NS + np.round(np.asarray(x) * 1e9).astype(np.int64)  # noqa: E731
    return to_ns(np.concatenate(ts)), np.vstack(qs), to_ns(tm)


def write_bag(out: Path, names: list[str], q: np.ndarray, d: np.ndarray, markers: dict[str, np.ndarray],
              storage: str = "mcap") -> Path:
    """rosbag2 at `out` (storage ``mcap`` or ``sqlite3``): ``/joint_states`` (JointState of `names`, no
    efforts) and per topic of `markers` {topic: (n, 3) m} one PointStamped a posture."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.LATEST)
    T = store.types
    tj, qj, tm = stream(q, d)

    def header(t_ns: int, frame: str):
        return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=int(t_ns) // 10**9,
                                                                             nanosec=int(t_ns) % 10**9), frame_id=frame)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    events = [(int(t), 0, k) for k, t in enumerate(tj)] + [(int(t), 1, k) for k, t in enumerate(tm)]
    with Writer(out, version=9, storage_plugin=plugin) as w:
        cj = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=store)
        cm = {tp: w.add_connection(tp, "geometry_msgs/msg/PointStamped", typestore=store) for tp in markers}
        for t, kind, k in sorted(events):
            if kind == 0:
                msg = T["sensor_msgs/msg/JointState"](header=header(t, ""), name=list(names), position=qj[k],
                                                      velocity=np.zeros(0), effort=np.zeros(0))
                w.write(cj, t, bytes(store.serialize_cdr(msg, "sensor_msgs/msg/JointState")))
                continue
            for tp, c in cm.items():
                y = markers[tp][k]
                p = T["geometry_msgs/msg/Point"](x=float(y[0]), y=float(y[1]), z=float(y[2]))
                m = T["geometry_msgs/msg/PointStamped"](header=header(t, "mocap"), point=p)
                w.write(c, t, bytes(store.serialize_cdr(m, c.msgtype)))
    return out
