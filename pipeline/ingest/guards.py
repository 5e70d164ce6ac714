"""Checks that run before any numeric conversion of a recording's content, so that hostile
input is a one-line error naming file, channel or metadata record and field — not a traceback.

* `check_metadata`: `campaign.system` a string; every number in the robot model and fixture
  finite and within ±1e6 (m, rad); joint limits finite with lower < upper; the robot model
  against its JSON Schema.
* `first_schema_error`: the first message of a channel that breaks the channel's JSON Schema, or
  holds an integer beyond int64 (the schema's `integer` has no range).
"""

from __future__ import annotations

import math
from collections.abc import Iterator

from pipeline.errors import RobocalError, where
from pipeline.recording.schemas import CHANNELS, META_CAMPAIGN, META_FIXTURE, META_ROBOT, validator

BOUND = 1e6  # |number| in a robot model or fixture, m or rad: anything larger is damage, not geometry
INT64 = 2 ** 63


def _numbers(o: object, path: str = "") -> Iterator[tuple[str, float]]:
    """(JSON path, value) of every number in a decoded JSON value (iterative: no recursion limit)."""
    stack = [(path, o)]
    while stack:
        p, v = stack.pop()
        if isinstance(v, bool):
            continue
        if isinstance(v, (int, float)):
            yield p, v
        elif isinstance(v, dict):
            stack.extend((f"{p}.{k}" if p else str(k), x) for k, x in v.items())
        elif isinstance(v, list):
            stack.extend((f"{p}[{i}]", x) for i, x in enumerate(v))


def check_metadata(rec) -> None:
    """Raise `RobocalError` (file, metadata record, field) for metadata no model should be built from."""
    camp = rec.metadata.get(META_CAMPAIGN)
    if camp is not None and "system" in camp and not isinstance(camp["system"], str):
        raise RobocalError(f"{rec.path}: metadata {META_CAMPAIGN!r}: field 'system' is "
                           f"{type(camp['system']).__name__}, expected a string")
    for name in (META_ROBOT, META_FIXTURE):
        doc = rec.metadata.get(name)
        if doc is None:
            continue
        for p, v in _numbers(doc):
            try:
                bad = not math.isfinite(v) or abs(v) > BOUND
            except OverflowError:  # an int too large for a float
                bad = True
            if bad:
                raise RobocalError(f"{rec.path}: metadata {name!r}: field {p} = {v!r:.40} is not a finite number "
                                   f"within ±{BOUND:g} (m, rad)")
    robot = rec.metadata.get(META_ROBOT)
    if robot is None:
        return
    from jsonschema.exceptions import best_match

    err = best_match(validator("robot_model").iter_errors(robot))
    if err is not None:
        loc = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in err.absolute_path).lstrip(".")
        raise RobocalError(f"{rec.path}: metadata {META_ROBOT!r}: {loc or 'record'}: {err.message[:160]}")
    joints = robot.get("joints") if isinstance(robot.get("joints"), list) else []
    for i, j in enumerate(joints):
        lo, hi = j.get("lower"), j.get("upper")
        if lo is not None and hi is not None and not lo < hi:
            raise RobocalError(f"{rec.path}: metadata {META_ROBOT!r}: joints[{i}] ({j.get('name', '?')}): "
                               f"joint limits lower {lo} ≥ upper {hi} (swapped?)")
    lo, hi = robot.get("lower"), robot.get("upper")
    if isinstance(lo, (int, float)) and isinstance(hi, (int, float)) and not lo < hi:
        raise RobocalError(f"{rec.path}: metadata {META_ROBOT!r}: actuator limits lower {lo} ≥ upper {hi} (swapped?)")


def first_schema_error(rec, topic: str) -> str | None:
    """'file: channel: record i: what' for the first message of `topic` that breaks its JSON Schema
    or holds an integer beyond int64; None when all conform (or robocal has no schema for it)."""
    if not rec.messages.raw.get(topic):  # renamed, another system's, or never written
        return rec.missing(topic)
    stem = CHANNELS.get(topic)
    if stem is None:
        return None
    from jsonschema.exceptions import best_match

    v = validator(stem)
    for i, m in enumerate(rec.messages[topic]):
        err = best_match(v.iter_errors(m))
        if err is not None:
            loc = ".".join(map(str, err.absolute_path)) or "message"
            return f"{where(rec.path, topic, i)}: {loc}: {err.message[:160]} (schema {stem})"
        for p, x in _numbers(m):
            if (isinstance(x, int) or "_ns" in p) and not -INT64 <= x < INT64:  # orjson reads 2**70 as a float
                return f"{where(rec.path, topic, i)}: {p}: integer {x!r:.30} is out of range (int64)"
            if isinstance(x, float) and not math.isfinite(x):
                return f"{where(rec.path, topic, i)}: {p}: {x} is not a finite number"
    return None
