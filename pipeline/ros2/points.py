"""ROS 2 bags → the measurement table of a URDF robot (`robocal import ros2`, `robocal run BAG`).

Reads with **rosbags** (pure Python; rosbag2 folders, MCAP and SQLite3 storage, CDR decoding with
its standard message store): ``sensor_msgs/msg/JointState`` on the joint topic, matched to the URDF
chain's joints by name (any order, other joints ignored), and ``geometry_msgs/msg/PointStamped`` or
``PoseStamped`` on the measurement topic (positions in m in the instrument frame ``header.frame_id``,
orientations as unit quaternions x, y, z, w).  Times are the messages' ``header.stamp`` (the
sensors' own clocks, ns), or the bag's receive times where a topic has no stamps.  Each measurement
is paired with the joint state where the robot stood still around it (`standstill.pair`); the rest
are reported and left out; a point measurement gets each joint's direction of approach, the sign of
its last motion in the joint states before it (the ``approach`` field: what a backlash term needs).  Where every JointState carries ``effort`` (the drive's measured torque,
N·m; force N for a prismatic joint), the joint states go into the recording's encoder stream with
their efforts, name-matched like the positions (`robocal.JointStateBatch` field 8), for the diagnosis.  Every input problem is one `RobocalError` line naming the file, topic
and record.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError
from pipeline.importers import standstill
from pipeline.importers.bounds import check_values
from pipeline.ros2.messages import (  # noqa: F401 — the names other importers use from here
    JOINT_STATE,
    MEASURE_TYPES,
    POINT,
    POSE,
    _decoder,
    _stamp,
    _times,
    at,
    read_measurements,
)
from pipeline.models.urdf import RobotDescription



@dataclass(frozen=True)
class BagSpec:
    """Which topics to read and how to pair them (SI: s, rad/s or m/s)."""

    joint_topic: str = "/joint_states"
    measure_topic: str | None = None  # None: the bag's only PointStamped / PoseStamped topic
    measure: str | None = None  # point | pose; None: from the measurement topic's type
    window_s: float = standstill.DEFAULT_WINDOW_S
    max_speed: float = standstill.DEFAULT_MAX_SPEED
    time: str = "header"  # header (header.stamp, falling back to receive time) | log (receive time)
    tips: tuple = ()  # ((link, PointStamped topic), …): a tree measured on several tips, one topic each


def _topics_line(topics: dict[str, str]) -> str:
    return ", ".join(f"{t} ({ty})" for t, ty in sorted(topics.items())) or "none"


def choose_joint_topic(path: Path, topics: dict[str, str], jt: str) -> str:
    """The joint topic `jt` checked against the bag's topic → type map."""
    js = sorted(t for t, ty in topics.items() if ty == JOINT_STATE)
    if jt not in topics:
        if not js:
            raise RobocalError(f"{path}: no {JOINT_STATE} topic in the bag (topics: {_topics_line(topics)})")
        raise RobocalError(f"{at(path, jt)}: not in the bag; {JOINT_STATE} topics: {', '.join(js)} (--joint-topic)")
    if topics[jt] != JOINT_STATE:
        raise RobocalError(f"{at(path, jt)}: is {topics[jt]}, expected {JOINT_STATE} (--joint-topic)")
    return jt


def choose_topics(path: Path, topics: dict[str, str], spec: BagSpec) -> tuple[str, str, str]:
    """(joint topic, measurement topic, measure) checked against the bag's topic → type map."""
    jt = choose_joint_topic(path, topics, spec.joint_topic)
    mt = spec.measure_topic
    cands = sorted(t for t, ty in topics.items() if ty in MEASURE_TYPES)
    if mt is None:
        if len(cands) != 1:
            camera = not cands and any(ty.startswith(("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"))
                                       for ty in topics.values())
            raise RobocalError(f"{path}: {'several' if cands else 'no'} PointStamped / PoseStamped topics "
                               f"({', '.join(cands) or _topics_line(topics)}): name one with --measure-topic"
                               + ("; a camera bag: `robocal import ros2 BAG --target BOARD …` (docs/guide/import-ros2.md)"
                                  if camera else ""))
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


def split(messages, joint_topic: str, side: list, several: bool = False):
    """Yield (receive time ns, CDR bytes) of the joint topic from `messages` ((topic, time, bytes), bag
    order), one at a time (the long topic is never held whole); the other topics' go to `side` as
    (receive time, bytes) or, `several`, (topic, receive time, bytes)."""
    for topic, t, data in messages:
        if topic == joint_topic:
            yield t, data
        else:
            side.append((topic, t, bytes(data)) if several else (t, bytes(data)))


class _Rows:
    """Rows appended one at a time into preallocated blocks (no Python object per row)."""

    def __init__(self, width: int, dtype=float, block: int = 65536) -> None:
        self.width, self.dtype, self.block = width, dtype, block
        self.done: list[np.ndarray] = []
        self.cur = np.empty((block, width), dtype)
        self.n = 0

    def append(self, row) -> None:
        if self.n == self.block:
            self.done.append(self.cur)
            self.cur = np.empty((self.block, self.width), self.dtype)
            self.n = 0
        self.cur[self.n] = row
        self.n += 1

    def array(self) -> np.ndarray:
        return np.concatenate([*self.done, self.cur[:self.n]])


def read_joint_states(path: Path, topic: str, messages, joints: list[str]):
    """Every JointState of `messages` ((receive time ns, CDR bytes), streamed) that names the chain's
    joints → (header stamps ns (n,), receive times ns (n,), positions (n, J) rad/m in `joints` order,
    report, efforts (n, J) N·m / N or None).  One naming only other joints is skipped and counted.
    Efforts are kept when every used message has one per name; some with and some without, an effort
    count that is neither 0 nor one per name, or NaN/inf is one line naming the record."""
    decode = _decoder(path, topic, JOINT_STATE)
    J = len(joints)
    Q = _Rows(J)
    E = _Rows(J)
    with_effort: list[int] = []  # record of the first used message with efforts, and of the first without
    without: list[int] = []
    T = _Rows(2, np.int64)  # header stamp, receive time
    rec = _Rows(1, np.int64)  # record index on the topic
    prev: list | None = None
    idx = np.zeros(J, np.intp)
    seen: set[str] = set()
    ignored: set[str] = set()
    n = 0
    for i, (log_t, data) in enumerate(messages):
        n += 1
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
        Q.append(pos[idx])
        eff = msg.effort
        if len(eff) == len(prev):
            E.append(np.asarray(eff, float)[idx])
            with_effort[:] = with_effort or [i]
        elif len(eff) == 0:
            without[:] = without or [i]
        else:
            raise RobocalError(f"{at(path, topic, i)}: {len(eff)} efforts for {len(prev)} joint names")
        T.append((_stamp(msg), log_t))
        rec.append(i)
    if n == 0:
        raise RobocalError(f"{at(path, topic)}: no messages")
    q, t, r = Q.array(), T.array(), rec.array()[:, 0]
    if len(q) == 0:
        raise RobocalError(f"{at(path, topic)}: joint names match none of the URDF chain's "
                           f"(chain: {', '.join(joints)}; bag: {', '.join(sorted(seen)) or 'none'})")
    bad = np.argwhere(~np.isfinite(q))
    if len(bad):
        i, k = bad[0]
        raise RobocalError(f"{at(path, topic, int(r[i]))}: joint {joints[k]!r} position is NaN or inf")
    check_values(lambda i: f"{at(path, topic, int(r[i // J]))}: joint {joints[i % J]!r} position", q.ravel())
    report = {"n_messages": n, "n_used": len(q), "n_skipped_other_joints": n - len(q), "ignored_joints": sorted(ignored)}
    effort = None
    # efforts are optional (many drivers publish NaN or none for joints without torque sensing): when they
    # are not complete and finite, the import goes on without them and says why
    if with_effort and without:
        report["efforts_dropped"] = (f"{at(path, topic, without[0])}: JointState without effort, but record "
                                     f"{with_effort[0]} has them: efforts not imported (kept only when every joint "
                                     "state carries them)")
    elif with_effort:
        effort = E.array()
        bad = np.argwhere(~np.isfinite(effort))
        if len(bad):
            i, k = bad[0]
            report["efforts_dropped"] = (f"{at(path, topic, int(r[i]))}: joint {joints[k]!r} effort is NaN or inf: "
                                         "efforts not imported")
            effort = None
        else:
            report["efforts"] = True
    return t[:, 0], t[:, 1], q, report, effort


APPROACH_SOURCE = "joint states: the sign of each joint's last motion before the measurement"


def _approach(tj: np.ndarray, Q: np.ndarray, tm: np.ndarray) -> np.ndarray | None:
    """(n, J) int8 direction of approach of each joint at the measurement times `tm` (ns) from the joint
    states (`tj` sorted ns, `Q` rad / m): the sign of its last motion (`last_motion_sign`); None where no
    joint moved before any measurement."""
    from pipeline.ingest.context import last_motion_sign

    d = last_motion_sign(tj, Q, tm).astype(np.int8)
    return d if d.any() else None


def read_bag(bag, desc: RobotDescription, spec: BagSpec = BagSpec()) -> tuple[dict, dict]:
    """(table for `write_urdf_recording`, campaign extras) of an open `pipeline.ros2.bag.Bag`: the paired
    measurements (joint positions in the chain's order, rad / m; positions m; orientations x,y,z,w); where
    the joint states carry efforts, ``table["stream"]``: the encoder stream for `write_urdf_recording`'s
    `stream` (t_ns (T,), q (T, J), effort (T, J) N·m).  `bag` may be the bag's path (opened here)."""
    from pipeline.ros2.bag import Bag

    if not isinstance(bag, Bag):
        with Bag(bag) as b:
            return read_bag(b, desc, spec)
    path = bag.path
    if spec.time not in ("header", "log"):
        raise RobocalError(f"--time {spec.time!r}: expected header or log")
    joints = desc.joint_names

    from pipeline.ros2.tips import tip_measurements, tip_topics

    def topics_of(topics):
        if spec.tips:
            mts = tip_topics(path, topics, spec)
            return choose_topics(path, topics, BagSpec(joint_topic=spec.joint_topic, measure_topic=mts[0]))[0], \
                mts, "point"
        jt, mt, measure = choose_topics(path, topics, spec)
        return jt, mt, measure

    def one_pass(b):
        side: list = []
        topics = b.topics
        jt, mts, measure = topics_of(topics)
        wanted = [jt, *(mts if spec.tips else [mts])]
        got = read_joint_states(path, jt, split(b.messages(wanted), jt, side, bool(spec.tips)), joints)
        return topics, jt, mts, measure, side, got

    topics, jt, mts, measure, side, (js, jlog, Q, jreport, effort) = bag.read(one_pass)
    warnings: list[str] = list(bag.warnings)
    data_lost: list[str] = list(bag.data_lost)
    mt = ", ".join(mts) if spec.tips else mts
    tj, jsrc = _times(js, jlog, spec.time == "header")
    if spec.tips:
        ms, P, O, frame, tm, msrc, target = tip_measurements(path, topics, mts, side, spec.time == "header")
    else:
        if not side:
            raise RobocalError(f"{at(path, mt)}: no messages")
        ms, P, O, frame = read_measurements(path, mt, topics[mt], [d for _, d in side])
        tm, msrc = _times(ms, [t for t, _ in side], spec.time == "header")
        target = np.zeros(len(tm), int)
    if jsrc != msrc:
        warnings.append(f"{path}: joint states timed by {jsrc}, measurements by {msrc} (a topic without "
                        "header stamps): the pairing assumes one clock")
    order = np.argsort(tj, kind="stable")
    tj, Q = tj[order], Q[order]
    effort = None if effort is None else effort[order]
    t0 = int(min(tj[0], tm.min()))
    pairing = standstill.pair((tj - t0) * 1e-9, Q, (tm - t0) * 1e-9, spec.window_s, spec.max_speed)
    summ = standstill.summary(pairing, (tm - t0) * 1e-9, joints)
    ok = pairing.still
    if not ok.any():
        raise RobocalError(f"{at(path, mt)}: none of the {len(tm)} measurements was taken while the robot stood "
                           f"still ({summ['n_moving']} moving, {summ['n_not_covered']} outside the joint states; "
                           f"window {spec.window_s} s, max speed {spec.max_speed}; see --still-window-s, --still-speed-rad-s)")
    keep = np.flatnonzero(ok)
    keep = keep[np.argsort(tm[keep], kind="stable")]  # recorded in time order (bag order is receive order)
    table: dict = {"joint_positions": pairing.q[keep], "position": P[keep], "timestamp_ns": tm[keep]}
    if measure == "pose":
        table["orientation"] = O[keep]
    else:
        table["target"] = target[keep]
        approach = _approach(tj, Q, tm[keep])
        if approach is not None:
            table["approach"] = approach
    extras = {
        "source_files": [str(path)],
        "ros2": {"joint_topic": jt, "measure_topic": mt, "measure_type": POINT if spec.tips else topics[mt],
                 "frame_id": frame,
                 "time_joint_states": jsrc, "time_measurements": msrc, "t0_ns": t0, "joint_states": jreport,
                 "pairing": summ, "measurement_records": keep.tolist()},
    }
    if measure == "point":
        extras["n_targets"] = 1
        if "approach" in table:
            extras["ros2"]["approach"] = APPROACH_SOURCE
    if spec.tips:
        extras["ros2"]["tip_topics"] = {link: topic for link, topic in spec.tips}
    if warnings:
        extras["import_warnings"] = warnings
    if data_lost:
        extras["data_lost"] = data_lost
    if effort is not None:  # the joint states with their efforts, as the recording's encoder stream
        table["stream"] = {"t_ns": tj, "q": Q, "effort": effort}
    return table, extras

