"""The measurement topics of a ROS 2 bag of a robot measured on several links (`robocal import ros2
--measure-topic LINK=TOPIC`, one ``geometry_msgs/msg/PointStamped`` topic per tip): the topics checked,
and their measurements read as one table with the tip index of each row (`pipeline.ros2.points`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError
from pipeline.ros2.messages import MEASURE_TYPES, POINT, _times, at, read_measurements


def tip_topics(path: Path, topics: dict[str, str], spec) -> list[str]:
    """The measurement topic of each of `spec.tips`, checked: in the bag, PointStamped, each once."""
    out = []
    for link, topic in spec.tips:
        if topic not in topics:
            cands = sorted(t for t, ty in topics.items() if ty in MEASURE_TYPES)
            raise RobocalError(f"{at(path, topic)}: not in the bag (--measure-topic {link}={topic}); measurement "
                               f"topics: {', '.join(cands) or 'none'}")
        if topics[topic] != POINT:
            raise RobocalError(f"{at(path, topic)}: is {topics[topic]}; a tip's topic must be {POINT} "
                               f"(--measure-topic {link}={topic})")
        if topic in out:
            raise RobocalError(f"{at(path, topic)}: named for two tips (--measure-topic)")
        out.append(topic)
    if spec.measure not in (None, "point"):
        raise RobocalError(f"--measure {spec.measure!r}: several tips give point measurements")
    return out


def tip_measurements(path: Path, topics: dict, mts: list[str], side: list, use_header: bool):
    """The measurements of several tips' topics as one table: (stamps, positions, None, frame, times,
    time source, tip index (m,)); one instrument frame for all."""
    stamps, P, T, target, frame, src = [], [], [], [], None, None
    for k, topic in enumerate(mts):
        rows = [(t, d) for tp, t, d in side if tp == topic]
        if not rows:
            raise RobocalError(f"{at(path, topic)}: no messages")
        ms, p, _, fr = read_measurements(path, topic, topics[topic], [d for _, d in rows])
        if frame is not None and fr != frame:
            raise RobocalError(f"{at(path, topic)}: frame {fr!r}, but {mts[0]} is in {frame!r} (one instrument "
                               "frame per campaign)")
        frame = fr
        tm, s_ = _times(ms, [t for t, _ in rows], use_header)
        src = s_ if src in (None, s_) else "mixed"
        stamps.append(ms)
        P.append(p)
        T.append(tm)
        target.append(np.full(len(tm), k, int))
    return (np.concatenate(stamps), np.concatenate(P), None, frame or "", np.concatenate(T), src,
            np.concatenate(target))
