"""The temperature channel (`/arm/temperature`): readings → a checked stream → the
temperature rise at each measurement time.

Every problem is a `RobocalError` of one line naming file, channel and record (message index
on the channel): a missing field, NaN/inf, a reading outside the plausible range, time stamps
that do not increase (per sensor), and measurements the readings do not cover (before the
first reading, after the last, or inside a gap between readings).  The pure checks
(`problems`, `coverage_problems`) are shared with the validate stage.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import RobocalError, where

TEMPERATURE = "/arm/temperature"
PLAUSIBLE_K = (223.15, 373.15)  # −50 … 100 °C: anything else is a broken or unplugged sensor
MAX_GAP_S = 30.0  # a measurement may sit at most this far from a reading on either side (and
GAP_FACTOR = 10.0  # within GAP_FACTOR × the median reading interval, whichever is larger)


@dataclass(frozen=True)
class TemperatureStream:
    """The readings of one sensor: times (ns since epoch), temperatures (K), message index."""

    sensor: str
    location: str
    t_ns: np.ndarray
    kelvin: np.ndarray
    record: np.ndarray

    def __len__(self) -> int:
        return self.t_ns.size


def problems(t_ns: np.ndarray, kelvin: np.ndarray, record: np.ndarray) -> list[tuple[str, list[int], str]]:
    """(check name, records, reason) of each problem of one sensor's readings (pure)."""
    t = np.asarray(t_ns, np.int64)
    k = np.asarray(kelvin, float)
    rec = np.asarray(record, int)
    out = []
    bad = ~np.isfinite(k)
    if bad.any():
        out.append(("temperature_finite", rec[bad].tolist(), "temperature is NaN or inf"))
    lo, hi = PLAUSIBLE_K
    out_of = np.isfinite(k) & ((k < lo) | (k > hi))
    if out_of.any():
        i = int(np.flatnonzero(out_of)[0])
        out.append(("temperature_range", rec[out_of].tolist(),
                    f"temperature {k[i]:.2f} K outside the plausible {lo:.2f}–{hi:.2f} K (−50…100 °C; "
                    f"kelvin expected, not °C)"))
    back = np.flatnonzero(np.diff(t) <= 0) + 1
    if back.size:
        out.append(("temperature_time", rec[back].tolist(),
                    "time stamp not after the previous reading's (time must increase)"))
    return out


def max_gap_ns(t_ns: np.ndarray) -> int:
    """The largest tolerated distance between a measurement and a reading (ns)."""
    dt = np.diff(np.asarray(t_ns, np.int64))
    med = float(np.median(dt)) if dt.size else 0.0
    return int(max(MAX_GAP_S * 1e9, GAP_FACTOR * med))


def coverage_problems(t_ns: np.ndarray, meas_t_ns: np.ndarray) -> np.ndarray:
    """Indices of measurements the readings do not cover: more than `max_gap_ns` before the
    first reading or after the last, or in a gap with a reading farther than that on either side."""
    t = np.asarray(t_ns, np.int64)
    m = np.asarray(meas_t_ns, np.int64)
    if t.size == 0:
        return np.arange(m.size)
    gap = max_gap_ns(t)
    j = np.searchsorted(t, m)  # t[j-1] < m <= t[j]
    before = np.where(j > 0, m - t[np.maximum(j - 1, 0)], np.iinfo(np.int64).max)
    after = np.where(j < t.size, t[np.minimum(j, t.size - 1)] - m, np.iinfo(np.int64).max)
    # inside the readings both neighbours must be near; beyond either end, the nearest reading
    first, last = j == 0, j == t.size
    ok = np.where(first, after <= gap, np.where(last, before <= gap, (before <= gap) & (after <= gap)))
    return np.flatnonzero(~ok)


def _number(path, i: int, msg: dict, key: str, kind: type):
    if key not in msg:
        raise RobocalError(f"{where(path, TEMPERATURE, i)}: field {key!r} missing")
    v = msg[key]
    if isinstance(v, bool) or not isinstance(v, (int, float) if kind is float else int):
        raise RobocalError(f"{where(path, TEMPERATURE, i)}: field {key!r} is {v!r}, not a number")
    return v


def _sensor(rec, msgs: list, idx: list[int], name: str) -> TemperatureStream:
    t = np.array([_number(rec.path, i, msgs[i], "timestamp_ns", int) for i in idx], np.int64)
    k = np.array([_number(rec.path, i, msgs[i], "temperature_k", float) for i in idx], float)
    rec_i = np.asarray(idx, int)
    for _name, bad, reason in problems(t, k, rec_i):
        raise RobocalError(f"{where(rec.path, TEMPERATURE, bad[0])}: {reason}")
    return TemperatureStream(name, str(msgs[idx[0]].get("location", "")), t, k, rec_i)


def temperature_streams(rec) -> list[TemperatureStream]:
    """The readings of every sensor, in the order of their first reading ([] when the channel is
    absent or empty).  Raises a one-line `RobocalError` on the first problem (`problems`)."""
    if not rec.messages.raw.get(TEMPERATURE):
        return []
    msgs = rec.messages[TEMPERATURE]
    sensors = [m.get("sensor") for m in msgs]
    for i, nm in enumerate(sensors):
        if not isinstance(nm, str) or not nm:
            raise RobocalError(f"{where(rec.path, TEMPERATURE, i)}: field 'sensor' missing or empty")
    names = list(dict.fromkeys(sensors))
    return [_sensor(rec, msgs, [i for i, s in enumerate(sensors) if s == nm], nm) for nm in names]


def temperature_stream(rec) -> TemperatureStream | None:
    """The readings of the recording's first sensor (None when the channel is absent or
    empty).  Raises a one-line `RobocalError` on the first problem (`problems`)."""
    if not rec.messages.raw.get(TEMPERATURE):
        return None
    msgs = rec.messages[TEMPERATURE]
    sensors = [m.get("sensor") for m in msgs]
    first = sensors[0]
    if not isinstance(first, str) or not first:
        raise RobocalError(f"{where(rec.path, TEMPERATURE, 0)}: field 'sensor' missing or empty")
    return _sensor(rec, msgs, [i for i, s in enumerate(sensors) if s == first], first)


def rise_at(stream: TemperatureStream, meas_t_ns: np.ndarray, path: object = "", channel: str = "",
            records: np.ndarray | None = None) -> np.ndarray:
    """Temperature rise since the first reading (K) at each measurement time (linear
    interpolation of the readings); a one-line `RobocalError` naming the first measurement
    (its `records` entry, default its index) the readings do not cover."""
    m = np.asarray(meas_t_ns, np.int64)
    bad = coverage_problems(stream.t_ns, m)
    if bad.size:
        i = int(bad[0]) if records is None else int(np.asarray(records)[bad[0]])
        span = (stream.t_ns[-1] - stream.t_ns[0]) * 1e-9
        raise RobocalError(
            f"{where(path, channel or None, i)}: no {TEMPERATURE} reading of sensor {stream.sensor!r} within "
            f"{max_gap_ns(stream.t_ns) * 1e-9:.0f} s of this measurement ({bad.size} measurement(s) not covered; "
            f"readings span {span:.0f} s from record {int(stream.record[0])})")
    t0 = stream.t_ns[0]
    return np.interp((m - t0) * 1e-9, (stream.t_ns - t0) * 1e-9, stream.kelvin) - stream.kelvin[0]
