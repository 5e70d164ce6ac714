"""ROS 2 message types robocal reads from a bag and how one measurement topic is decoded (rosbags' CDR
deserialiser): the topic types, the error prefix naming file, topic and record, header stamps (ns) and
the positions (m) and orientations (x, y, z, w) of PointStamped / PoseStamped messages."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError
from pipeline.importers.bounds import check_values

JOINT_STATE = "sensor_msgs/msg/JointState"
POINT = "geometry_msgs/msg/PointStamped"
POSE = "geometry_msgs/msg/PoseStamped"
MEASURE_TYPES = {POINT: "point", POSE: "pose"}


def at(path: Path, topic: str, record: int | None = None) -> str:
    """'file: topic /x: record 12' — the prefix of every bag input error."""
    return f"{path}: topic {topic}" + ("" if record is None else f": record {record}")


def _decoder(path: Path, topic: str, typename: str):
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.LATEST)

    def decode(i: int, data: bytes):
        try:
            return store.deserialize_cdr(data, typename)
        except Exception as e:  # noqa: BLE001 — the library's errors (SerdeError, struct, …) are the data's
            raise RobocalError(f"{at(path, topic, i)}: CDR does not decode as {typename} "
                               f"({type(e).__name__}: {e})") from None
    return decode


def _stamp(msg) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def read_measurements(path: Path, topic: str, typename: str, datas: list[bytes]):
    """(header stamps ns (m,), positions (m, 3) m, orientations (m, 4) x,y,z,w or None, frame id)."""
    decode = _decoder(path, topic, typename)
    m = len(datas)
    P = np.empty((m, 3))
    O = np.empty((m, 4)) if typename == POSE else None
    stamps = np.empty(m, np.int64)
    frame = None
    for i, data in enumerate(datas):
        msg = decode(i, data)
        if frame is None:
            frame = msg.header.frame_id
        elif msg.header.frame_id != frame:
            raise RobocalError(f"{at(path, topic, i)}: frame {msg.header.frame_id!r}, but earlier measurements "
                               f"are in {frame!r} (one instrument frame per campaign)")
        stamps[i] = _stamp(msg)
        if O is None:
            P[i] = (msg.point.x, msg.point.y, msg.point.z)
        else:
            p, o = msg.pose.position, msg.pose.orientation
            P[i] = (p.x, p.y, p.z)
            O[i] = (o.x, o.y, o.z, o.w)
    bad = np.flatnonzero(~np.isfinite(P).all(1) | (False if O is None else ~np.isfinite(O).all(1)))
    if len(bad):
        raise RobocalError(f"{at(path, topic, int(bad[0]))}: position or orientation is NaN or inf")
    check_values(lambda i: f"{at(path, topic, i // 3)}: position {'xyz'[i % 3]}", P.ravel(), "m")
    if O is not None:
        norm = np.linalg.norm(O, axis=1)
        zero = np.flatnonzero(norm < 1e-9)
        if len(zero):
            raise RobocalError(f"{at(path, topic, int(zero[0]))}: orientation quaternion is zero")
        O = O / norm[:, None]
    return stamps, P, O, frame or ""


def _times(stamps: np.ndarray, log, use_header: bool) -> tuple[np.ndarray, str]:
    if use_header and np.all(stamps > 0):
        return stamps, "header.stamp"
    return np.asarray(log, np.int64), "receive time"
