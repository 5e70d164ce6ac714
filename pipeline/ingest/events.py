"""Controller events beside the measurements (the recording contract: payload changes, search commands, faults):

- ``/arm/payload`` (`payload.schema.json`): a payload / tool change at the time it happens →
  the payload schedule [{t_ns, payload_kg, tool}] (replaces the campaign metadata's schedule,
  which older recordings still carry);
- ``search`` of each ``/touch/contact`` (optional): the commanded search speed (m/s), direction
  and stand-off → columns ``search_speed_m_s`` (n,) (NaN where absent), ``search_direction`` (n, 3);
- ``/touch/miss`` with reason ``fault`` (and ``no_contact`` / ``contact_at_approach``): the
  searches that gave no contact, counted per reason with the faulted ones listed.

Every problem is a one-line `RobocalError` naming file, channel and record.
"""

from __future__ import annotations

import numpy as np

from pipeline.errors import RobocalError, where

PAYLOAD = "/arm/payload"
TOUCH_CONTACT = "/touch/contact"
TOUCH_MISS = "/touch/miss"
MAX_PAYLOAD_KG = 1e4  # beyond any arm: a unit or sign error


def _num(path, topic: str, i: int, msg: dict, key: str, integer: bool = False) -> float | int:
    if key not in msg:
        raise RobocalError(f"{where(path, topic, i)}: field {key!r} missing")
    v = msg[key]
    ok = isinstance(v, int) if integer else isinstance(v, (int, float))
    if isinstance(v, bool) or not ok or (not integer and not np.isfinite(v)):
        raise RobocalError(f"{where(path, topic, i)}: field {key!r} is {v!r}, not a finite number")
    return v


def payload_schedule(rec) -> list[dict] | None:
    """The payload schedule from `/arm/payload` (None when the channel is absent or empty)."""
    if not rec.messages.raw.get(PAYLOAD):
        return None
    out, last = [], None
    for i, m in enumerate(rec.messages[PAYLOAD]):
        t = int(_num(rec.path, PAYLOAD, i, m, "timestamp_ns", integer=True))
        kg = float(_num(rec.path, PAYLOAD, i, m, "payload_kg"))
        if not 0 <= kg <= MAX_PAYLOAD_KG:
            raise RobocalError(f"{where(rec.path, PAYLOAD, i)}: payload_kg {kg!r} outside 0…{MAX_PAYLOAD_KG:g} kg")
        if last is not None and t <= last:
            raise RobocalError(f"{where(rec.path, PAYLOAD, i)}: time stamp not after the previous change's")
        last = t
        out.append({"t_ns": t, "payload_kg": kg, **({"tool": str(m["tool"])} if "tool" in m else {})})
    return out


def search_commands(rec) -> dict[str, np.ndarray] | None:
    """``search_speed_m_s`` (n,) and ``search_direction`` (n, 3) of the contacts (NaN where a contact
    has no `search`); None when no contact has one."""
    msgs = rec.messages[TOUCH_CONTACT] if rec.messages.raw.get(TOUCH_CONTACT) else []
    if not any("search" in m for m in msgs):
        return None
    n = len(msgs)
    speed, direction = np.full(n, np.nan), np.full((n, 3), np.nan)
    for i, m in enumerate(msgs):
        s = m.get("search")
        if s is None:
            continue
        if not isinstance(s, dict):
            raise RobocalError(f"{where(rec.path, TOUCH_CONTACT, i)}: field 'search' is not an object")
        v = float(_num(rec.path, TOUCH_CONTACT, i, s, "speed_m_s"))
        if v <= 0:
            raise RobocalError(f"{where(rec.path, TOUCH_CONTACT, i)}: search speed_m_s {v!r} is not positive")
        speed[i] = v
        if "direction" in s:
            try:
                d = np.asarray(s["direction"], float) if isinstance(s["direction"], list) else np.zeros(0)
            except (TypeError, ValueError):
                d = np.zeros(0)
            if d.shape != (3,) or not np.all(np.isfinite(d)) or abs(np.linalg.norm(d) - 1) > 1e-3:
                raise RobocalError(f"{where(rec.path, TOUCH_CONTACT, i)}: search direction {s['direction']!r} "
                                   "is not a unit 3-vector")
            direction[i] = d
    return {"search_speed_m_s": speed, "search_direction": direction}


def misses(rec) -> dict:
    """{reason: count} of `/touch/miss` and the faulted searches [{record, face, fault_code}]."""
    if not rec.messages.raw.get(TOUCH_MISS):
        return {"counts": {}, "faults": []}
    counts: dict[str, int] = {}
    faults = []
    for i, m in enumerate(rec.messages[TOUCH_MISS]):
        reason = m.get("reason")
        if reason not in ("no_contact", "contact_at_approach", "fault"):
            raise RobocalError(f"{where(rec.path, TOUCH_MISS, i)}: reason {reason!r} is not no_contact, "
                               "contact_at_approach or fault")
        counts[reason] = counts.get(reason, 0) + 1
        if reason == "fault":
            faults.append({"record": i, "face": str(m.get("face", "")), "fault_code": str(m.get("fault_code", ""))})
    return {"counts": counts, "faults": faults}
