"""Named checks of a recording (pure functions over decoded messages and tables).

Every check returns `Check`s: a name, ``pass``/``warn``/``fail``, a one-line message, the
channel and the records (message index on that channel) concerned.  A fail stops the run.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from typing import Callable, Sequence

import numpy as np

PASS, WARN, FAIL = "pass", "warn", "fail"
MAX_LISTED = 5  # records quoted in a message (all are listed in `records`)


@dataclass(frozen=True)
class Check:
    name: str
    status: str
    message: str
    channel: str = ""
    records: list[int] = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)


def _quote(records: Sequence[int]) -> str:
    r = list(records)
    more = f" and {len(r) - MAX_LISTED} more" if len(r) > MAX_LISTED else ""
    return ", ".join(str(i) for i in r[:MAX_LISTED]) + more


def make(name: str, channel: str, bad: Sequence[int], status_if_bad: str, ok: str, bad_text: str) -> Check:
    """A check that passes when `bad` is empty; else names its records."""
    bad = sorted({int(i) for i in bad})
    if not bad:
        return Check(name, PASS, ok, channel, [])
    return Check(name, status_if_bad, f"{channel}: {len(bad)} record(s) ({_quote(bad)}): {bad_text}", channel, bad)


# ----- schema conformance -------------------------------------------------------------------
def _representative(v: list) -> list | None:
    """For a long homogeneous numeric (nested) list, the same nesting with one element that
    stands for all (a non-integral one if any), so jsonschema checks its type once; None when
    the list is not a rectangular array of numbers (then it is validated in full)."""
    try:
        a = np.asarray(v)
    except ValueError:
        return None
    if a.dtype.kind not in "iuf" or a.size == 0:
        return None
    flat = a.ravel()
    if a.dtype.kind == "f":
        frac = flat != np.floor(flat)
        rep = flat[int(np.argmax(frac))] if frac.any() else flat[0]
        rep = float(rep)
    else:
        rep = int(flat[0])
    out: object = rep
    for _ in range(a.ndim):
        out = [out]
    return out  # type: ignore[return-value]


def thin(msg: dict, min_len: int = 64) -> dict:
    """`msg` with every long numeric array reduced by `_representative` (where possible)."""
    out = {}
    for k, v in msg.items():
        if isinstance(v, list) and len(v) >= min_len:
            rep = _representative(v)
            out[k] = v if rep is None else rep
        else:
            out[k] = v
    return out


def check_schema(channel: str, messages: Sequence[dict], validator) -> Check:
    """Every message conforms to the channel's JSON Schema (`validator` from jsonschema;
    None for a channel robocal does not know)."""
    if validator is None:
        return Check("schema", WARN, f"{channel}: no schema known for this channel; not checked", channel, [])
    bad, first = [], ""
    for i, m in enumerate(messages):
        errs = list(validator.iter_errors(thin(m)))
        if errs:
            bad.append(i)
            if not first:
                e = errs[0]
                loc = "/".join(str(p) for p in e.absolute_path)
                first = f"record {i}: {loc + ': ' if loc else ''}{e.message}"
    return make("schema", channel, bad, FAIL, f"{channel}: {len(messages)} messages conform to the schema",
                f"do not conform to the schema (first: {first})")


# ----- time --------------------------------------------------------------------------------
def check_stream_time(channel: str, t_ns: np.ndarray, record: np.ndarray, gap_factor: float = 5.0) -> list[Check]:
    """Encoder sample times (ns) strictly increasing (fail) and without gaps longer than
    `gap_factor` × the median sample period (warn).  `record`: message of each sample."""
    t = np.asarray(t_ns, np.int64)
    rec = np.asarray(record)
    if t.size < 2:
        return [Check("time_monotonic", PASS, f"{channel}: fewer than 2 samples", channel, [])]
    dt = np.diff(t)
    back = np.flatnonzero(dt <= 0) + 1
    out = [make("time_monotonic", channel, rec[back], FAIL, f"{channel}: {t.size} sample times strictly increasing",
                "sample times do not increase (repeated or going back)")]
    period = float(np.median(dt[dt > 0])) if np.any(dt > 0) else 0.0
    gaps = np.flatnonzero(dt > gap_factor * period) + 1 if period > 0 else np.array([], int)
    longest = float(dt.max()) * 1e-9
    out.append(make("time_gaps", channel, rec[gaps], WARN,
                    f"{channel}: no gap longer than {gap_factor:g}× the {period * 1e-6:.3f} ms sample period",
                    f"gap(s) in the stream before these messages (longest {longest:.3f} s; "
                    f"period {period * 1e-6:.3f} ms)"))
    return out


def check_event_time(channel: str, t_ns: np.ndarray, stream_span: tuple[int, int] | None) -> list[Check]:
    """Measurement times non-decreasing (warn) and inside the encoder stream (warn)."""
    t = np.asarray(t_ns, np.int64)
    back = np.flatnonzero(np.diff(t) < 0) + 1
    out = [make("time_order", channel, back, WARN, f"{channel}: measurement times in order",
                "timestamp earlier than the previous measurement's")]
    if stream_span is not None:
        outside = np.flatnonzero((t < stream_span[0]) | (t > stream_span[1]))
        out.append(make("time_in_stream", channel, outside, WARN,
                        f"{channel}: every measurement inside the encoder stream's time span",
                        "timestamp outside the encoder stream (no motion context)"))
    return out


# ----- duplicates --------------------------------------------------------------------------
def _content_key(b: bytes | dict, ignore: tuple[str, ...]) -> bytes:
    """The message without its bookkeeping fields (time, sequence), for a repeated-reading test."""
    if isinstance(b, (bytes, bytearray)):
        try:
            b = json.loads(b)
        except ValueError:
            return bytes(b)
    if isinstance(b, dict):
        b = {k: v for k, v in b.items() if k not in ignore}
    return json.dumps(b, sort_keys=True).encode()


def check_duplicates(channel: str, bodies: Sequence[bytes | dict], t_ns: np.ndarray | None = None,
                     ignore: tuple[str, ...] = ("timestamp_ns", "seq", "record")) -> Check:
    """Messages whose body repeats an earlier one exactly, or (measurement channels, `t_ns`
    given) whose timestamp repeats an earlier one, or (measurement channels) whose content repeats
    an earlier one's apart from the `ignore` fields (the same configuration and reading at another
    time: a copied row adds no information).  Names the later copies."""
    seen: dict[bytes, int] = {}
    bad = []
    for i, b in enumerate(bodies):
        raw = b if isinstance(b, (bytes, bytearray)) else json.dumps(b, sort_keys=True).encode()
        h = hashlib.blake2b(raw, digest_size=16).digest()
        if h in seen:
            bad.append(i)
        else:
            seen[h] = i
    same = []
    if t_ns is not None:
        t = np.asarray(t_ns, np.int64)
        _, first = np.unique(t, return_index=True)
        bad += sorted(set(range(t.size)) - set(first.tolist()))
        content: dict[bytes, int] = {}
        for i, b in enumerate(bodies):
            h = hashlib.blake2b(_content_key(b, ignore), digest_size=16).digest()
            if h in content and i not in bad:
                same.append(i)
            content.setdefault(h, i)
    if same and not bad:
        distinct = len(bodies) - len(same)
        return make("duplicates", channel, same, WARN, "",
                    f"repeat an earlier measurement's configuration and reading at another time "
                    f"({distinct} distinct of {len(bodies)}): a repeated row adds no information")
    return make("duplicates", channel, bad + same, WARN, f"{channel}: no duplicated messages",
                "duplicate an earlier message (same body or same timestamp)"
                + (f"; {len(same)} more repeat an earlier one's configuration and reading" if same else ""))


# ----- NaN / inf ----------------------------------------------------------------------------
def _nonfinite(o: object) -> bool:
    if isinstance(o, float):
        return not np.isfinite(o)
    if isinstance(o, list):
        try:
            a = np.asarray(o, dtype=float)
        except (ValueError, TypeError):
            return any(_nonfinite(v) for v in o)
        return not bool(np.all(np.isfinite(a)))
    if isinstance(o, dict):
        return any(_nonfinite(v) for v in o.values())
    return False


def check_finite(channel: str, messages: Sequence[dict]) -> Check:
    bad = [i for i, m in enumerate(messages) if _nonfinite(m)]
    return make("finite", channel, bad, FAIL, f"{channel}: no NaN or infinite values", "contain NaN or infinite values")


# ----- joint limits ---------------------------------------------------------------------------
def check_joint_limits(channel: str, q: np.ndarray, record: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                       names: Sequence[str]) -> Check:
    """Joint values (rad) inside the robot model's travel limits."""
    q = np.asarray(q, float)
    out = (q < lower) | (q > upper)
    rows = np.flatnonzero(out.any(axis=1))
    joints = sorted({names[j] for j in np.flatnonzero(out.any(axis=0))})
    return make("joint_limits", channel, np.asarray(record)[rows], FAIL,
                f"{channel}: every joint value inside the model's limits",
                f"joint values outside the limits of {', '.join(joints)}")


# ----- touch-jig faces ------------------------------------------------------------------------
def check_face_coordinates(channel: str, face: np.ndarray, axis: np.ndarray, coordinate: np.ndarray,
                           record: np.ndarray, faces: dict[str, tuple[int, float]], tol_m: float = 1e-9) -> Check:
    """A contact's face must exist in the jig and its (axis, coordinate) must be that face's
    (axis index 0/1/2, drawing coordinate in m, to `tol_m`)."""
    bad = []
    first = ""
    for f, a, c, r in zip(face, np.asarray(axis, int), np.asarray(coordinate, float), record):
        if f not in faces:
            why = f"face {f!r} is not in the jig"
        elif faces[f][0] != a or abs(faces[f][1] - c) > tol_m:
            why = (f"face {f} fixes {'xyz'[faces[f][0]]} = {faces[f][1]:.6f} m, contact says "
                   f"{'xyz'[a]} = {c:.6f} m")
        else:
            continue
        bad.append(int(r))
        first = first or f"record {int(r)}: {why}"
    return make("face_coordinate", channel, bad, FAIL, f"{channel}: every contact matches its face",
                f"coordinate does not match the face (first: {first})")


# ----- gross outliers -----------------------------------------------------------------------
def robust_z(residuals: np.ndarray) -> np.ndarray:
    """|r − median| / (1.4826·MAD) per measurement, on the residual norm for k-vectors."""
    r = np.asarray(residuals, float)
    r = r[:, 0] if r.ndim == 2 and r.shape[1] == 1 else (np.linalg.norm(r, axis=1) if r.ndim == 2 else r)
    med = np.median(r)
    dev = np.abs(r - med)
    mad = 1.4826 * np.median(dev)
    if mad == 0:  # more than half the residuals equal: fall back to the mean absolute deviation
        mad = 1.2533 * np.mean(dev)
    if mad == 0:
        return np.zeros_like(r)
    return np.abs(r - med) / mad


def check_outliers(channel: str, residuals: np.ndarray, record: np.ndarray, threshold: float = 6.0) -> Check:
    """Measurements whose residual after a first (robust) fit is more than `threshold`
    robust standard deviations (MAD) from the median."""
    z = robust_z(residuals)
    bad = np.asarray(record)[z > threshold]
    worst = float(z.max()) if z.size else 0.0
    return make("outliers", channel, bad, WARN,
                f"{channel}: no residual beyond {threshold:g} robust σ (largest {worst:.1f})",
                f"gross outliers: residual beyond {threshold:g} robust σ (MAD) after a first fit")


CheckFn = Callable[..., Check | list[Check]]


# ----- temperature channel ----------------------------------------------------------------
def check_temperature(channel: str, messages: Sequence[dict], meas_t_ns: np.ndarray | None,
                      meas_channel: str = "", meas_record: np.ndarray | None = None) -> list[Check]:
    """Readings of each sensor: finite, plausible (kelvin), time increasing (fail); the
    measurements covered by readings (fail naming the measurement records)."""
    from pipeline.ingest.temperature import coverage_problems, max_gap_ns, problems

    out: list[Check] = []
    by_sensor: dict[str, list[int]] = {}
    for i, m in enumerate(messages):
        by_sensor.setdefault(str(m.get("sensor", "")), []).append(i)
    for sensor, idx in by_sensor.items():
        ok = [i for i in idx if isinstance(messages[i].get("timestamp_ns"), int)
              and isinstance(messages[i].get("temperature_k"), (int, float))]
        t = np.array([messages[i]["timestamp_ns"] for i in ok], np.int64)
        k = np.array([messages[i]["temperature_k"] for i in ok], float)
        found = problems(t, k, np.array(ok, int))
        for name, recs, reason in found:
            out.append(make(name, channel, recs, FAIL, "", f"sensor {sensor!r}: {reason}"))
        if not found:
            out.append(Check("temperature", PASS, f"{channel}: sensor {sensor!r}: {t.size} readings finite, "
                                                  f"plausible and in time order", channel, []))
        if meas_t_ns is not None and not found and sensor == next(iter(by_sensor)):
            bad = coverage_problems(t, meas_t_ns)
            recs = bad if meas_record is None else np.asarray(meas_record)[bad]
            out.append(make("temperature_coverage", meas_channel or channel, recs, FAIL,
                            f"{channel}: every measurement within {max_gap_ns(t) * 1e-9:.0f} s of a reading",
                            f"no {channel} reading of sensor {sensor!r} within {max_gap_ns(t) * 1e-9:.0f} s"))
    return out
