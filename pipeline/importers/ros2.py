"""ROS 2 bags → the measurement table of a URDF robot (`robocal import ros2`, `robocal run BAG`).

Reads with **rosbags** (pure Python; rosbag2 folders, MCAP and SQLite3 storage, CDR decoding with
its standard message store): ``sensor_msgs/msg/JointState`` on the joint topic, matched to the URDF
chain's joints by name (any order, other joints ignored), and ``geometry_msgs/msg/PointStamped`` or
``PoseStamped`` on the measurement topic (positions in m in the instrument frame ``header.frame_id``,
orientations as unit quaternions x, y, z, w).  Times are the messages' ``header.stamp`` (the
sensors' own clocks, ns), or the bag's receive times where a topic has no stamps.  Each measurement
is paired with the joint state where the robot stood still around it (`standstill.pair`); the rest
are reported and left out.  Every input problem is one `RobocalError` line naming the file, topic
and record.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError
from pipeline.importers import standstill
from pipeline.models.urdf import RobotDescription

JOINT_STATE = "sensor_msgs/msg/JointState"
POINT = "geometry_msgs/msg/PointStamped"
POSE = "geometry_msgs/msg/PoseStamped"
MEASURE_TYPES = {POINT: "point", POSE: "pose"}


@dataclass(frozen=True)
class BagSpec:
    """Which topics to read and how to pair them (SI: s, rad/s or m/s)."""

    joint_topic: str = "/joint_states"
    measure_topic: str | None = None  # None: the bag's only PointStamped / PoseStamped topic
    measure: str | None = None  # point | pose; None: from the measurement topic's type
    window_s: float = standstill.DEFAULT_WINDOW_S
    max_speed: float = standstill.DEFAULT_MAX_SPEED
    time: str = "header"  # header (header.stamp, falling back to receive time) | log (receive time)


def at(path: Path, topic: str, record: int | None = None) -> str:
    """'file: topic /x: record 12' — the prefix of every bag input error."""
    return f"{path}: topic {topic}" + ("" if record is None else f": record {record}")


def _open(path: Path):
    from rosbags.rosbag2 import Reader

    try:
        reader = Reader(path)
        reader.open()
    except Exception as e:  # noqa: BLE001 — any failure of the storage layer is the file's problem
        raise RobocalError(f"{path}: cannot read as a ROS 2 bag ({type(e).__name__}: {e})") from None
    return reader


def _topics_line(topics: dict[str, str]) -> str:
    return ", ".join(f"{t} ({ty})" for t, ty in sorted(topics.items())) or "none"


def choose_topics(path: Path, topics: dict[str, str], spec: BagSpec) -> tuple[str, str, str]:
    """(joint topic, measurement topic, measure) checked against the bag's topic → type map."""
    jt = spec.joint_topic
    js = sorted(t for t, ty in topics.items() if ty == JOINT_STATE)
    if jt not in topics:
        if not js:
            raise RobocalError(f"{path}: no {JOINT_STATE} topic in the bag (topics: {_topics_line(topics)})")
        raise RobocalError(f"{at(path, jt)}: not in the bag; {JOINT_STATE} topics: {', '.join(js)} (--joint-topic)")
    if topics[jt] != JOINT_STATE:
        raise RobocalError(f"{at(path, jt)}: is {topics[jt]}, expected {JOINT_STATE} (--joint-topic)")
    mt = spec.measure_topic
    cands = sorted(t for t, ty in topics.items() if ty in MEASURE_TYPES)
    if mt is None:
        if len(cands) != 1:
            raise RobocalError(f"{path}: {'several' if cands else 'no'} PointStamped / PoseStamped topics "
                               f"({', '.join(cands) or _topics_line(topics)}): name one with --measure-topic")
        mt = cands[0]
    if mt not in topics:
        raise RobocalError(f"{at(path, mt)}: not in the bag; measurement topics: {', '.join(cands) or 'none'} "
                           "(--measure-topic)")
    if topics[mt] not in MEASURE_TYPES:
        raise RobocalError(f"{at(path, mt)}: is {topics[mt]}, expected {POINT} or {POSE} (--measure-topic)")
    measure = spec.measure or MEASURE_TYPES[topics[mt]]
    if measure not in ("point", "pose"):
        raise RobocalError(f"--measure {measure!r}: a ROS 2 bag gives point or pose measurements")
    if measure == "pose" and topics[mt] != POSE:
        raise RobocalError(f"{at(path, mt)}: is {topics[mt]}, which has no orientation: use --measure point")
    return jt, mt, measure


def _raw(path: Path, reader, topics: tuple[str, ...]) -> dict[str, tuple[list[int], list[bytes]]]:
    """topic -> (receive times ns, CDR bytes) in bag order."""
    out: dict[str, tuple[list[int], list[bytes]]] = {t: ([], []) for t in topics}
    conns = [c for c in reader.connections if c.topic in topics]
    n = 0
    try:
        for conn, t, data in reader.messages(connections=conns):
            times, datas = out[conn.topic]
            times.append(t)
            datas.append(bytes(data))
            n += 1
    except Exception as e:  # noqa: BLE001
        raise RobocalError(f"{path}: cannot read the bag after message {n} ({type(e).__name__}: {e})") from None
    return out


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


def read_joint_states(path: Path, topic: str, datas: list[bytes], joints: list[str]):
    """(header stamps ns (n,), positions (n, J) in `joints` order, report): every JointState that
    names any chain joint; one naming only other joints is skipped and counted."""
    decode = _decoder(path, topic, JOINT_STATE)
    J = len(joints)
    Q = np.empty((len(datas), J))
    stamps = np.empty(len(datas), np.int64)
    keep = np.zeros(len(datas), bool)
    prev: list | None = None
    idx = np.zeros(J, np.intp)
    seen: set[str] = set()
    ignored: set[str] = set()
    for i, data in enumerate(datas):
        msg = decode(i, data)
        names = msg.name
        if names != prev:
            prev = list(names)
            seen.update(prev)
            pos_of = {nm: k for k, nm in enumerate(prev)}
            found = [j in pos_of for j in joints]
            if any(found) and not all(found):
                missing = [j for j, f in zip(joints, found) if not f]
                raise RobocalError(f"{at(path, topic, i)}: chain joint(s) {', '.join(missing)} missing from the "
                                   f"JointState names ({', '.join(prev)})")
            idx = np.array([pos_of.get(j, -1) for j in joints], np.intp)
            ignored.update(set(prev) - set(joints))
        if idx[0] < 0:
            continue
        pos = np.asarray(msg.position, float)
        if len(pos) != len(prev):
            raise RobocalError(f"{at(path, topic, i)}: {len(pos)} positions for {len(prev)} joint names")
        Q[i] = pos[idx]
        stamps[i] = _stamp(msg)
        keep[i] = True
    if not keep.any():
        raise RobocalError(f"{at(path, topic)}: joint names match none of the URDF chain's "
                           f"(chain: {', '.join(joints)}; bag: {', '.join(sorted(seen)) or 'none'})")
    bad = np.argwhere(~np.isfinite(Q) & keep[:, None])
    if len(bad):
        i, k = bad[0]
        raise RobocalError(f"{at(path, topic, int(i))}: joint {joints[k]!r} position is NaN or inf")
    report = {"n_messages": len(datas), "n_used": int(keep.sum()), "n_skipped_other_joints": int((~keep).sum()),
              "ignored_joints": sorted(ignored)}
    return stamps[keep], Q[keep], np.flatnonzero(keep), report


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
    if O is not None:
        norm = np.linalg.norm(O, axis=1)
        zero = np.flatnonzero(norm < 1e-9)
        if len(zero):
            raise RobocalError(f"{at(path, topic, int(zero[0]))}: orientation quaternion is zero")
        O = O / norm[:, None]
    return stamps, P, O, frame or ""


def _times(stamps: np.ndarray, log: list[int], use_header: bool) -> tuple[np.ndarray, str]:
    if use_header and np.all(stamps > 0):
        return stamps, "header.stamp"
    return np.asarray(log, np.int64), "receive time"


def read_bag(path: str | Path, desc: RobotDescription, spec: BagSpec = BagSpec()) -> tuple[dict, dict]:
    """(table for `write_urdf_recording`, campaign extras) of a ROS 2 bag: the paired measurements
    (joint positions in the chain's order, rad / m; positions m; orientations x,y,z,w)."""
    path = Path(path)
    if spec.time not in ("header", "log"):
        raise RobocalError(f"--time {spec.time!r}: expected header or log")
    reader = _open(path)
    try:
        topics = {t: (info.msgtype or "(several types)") for t, info in reader.topics.items()}
        jt, mt, measure = choose_topics(path, topics, spec)
        raw = _raw(path, reader, (jt, mt))
    finally:
        reader.close()
    if not raw[mt][1]:
        raise RobocalError(f"{at(path, mt)}: no messages")
    if not raw[jt][1]:
        raise RobocalError(f"{at(path, jt)}: no messages")
    joints = desc.joint_names
    js, Q, used, jreport = read_joint_states(path, jt, raw[jt][1], joints)
    tj, jsrc = _times(js, [raw[jt][0][i] for i in used], spec.time == "header")
    ms, P, O, frame = read_measurements(path, mt, topics[mt], raw[mt][1])
    tm, msrc = _times(ms, raw[mt][0], spec.time == "header")
    warnings = []
    if jsrc != msrc:
        warnings.append(f"{path}: joint states timed by {jsrc}, measurements by {msrc} (a topic without "
                        "header stamps): the pairing assumes one clock")
    order = np.argsort(tj, kind="stable")
    tj, Q = tj[order], Q[order]
    t0 = int(min(tj[0], tm.min()))
    pairing = standstill.pair((tj - t0) * 1e-9, Q, (tm - t0) * 1e-9, spec.window_s, spec.max_speed)
    summ = standstill.summary(pairing, (tm - t0) * 1e-9, joints)
    ok = pairing.still
    if not ok.any():
        raise RobocalError(f"{at(path, mt)}: none of the {len(tm)} measurements was taken while the robot stood "
                           f"still ({summ['n_moving']} moving, {summ['n_not_covered']} outside the joint states; "
                           f"window {spec.window_s} s, max speed {spec.max_speed}; see --still-window, --still-speed)")
    table: dict = {"joint_positions": pairing.q[ok], "position": P[ok], "timestamp_ns": tm[ok]}
    if measure == "pose":
        table["orientation"] = O[ok]
    else:
        table["target"] = np.zeros(int(ok.sum()), int)
    extras = {
        "source_files": [str(path)],
        "ros2": {"joint_topic": jt, "measure_topic": mt, "measure_type": topics[mt], "frame_id": frame,
                 "time_joint_states": jsrc, "time_measurements": msrc, "t0_ns": t0, "joint_states": jreport,
                 "pairing": summ, "measurement_records": np.flatnonzero(ok).tolist()},
    }
    if measure == "point":
        extras["n_targets"] = 1
    if warnings:
        extras["import_warnings"] = warnings
    return table, extras
