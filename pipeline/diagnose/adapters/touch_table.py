"""The diagnosis table: each measurement with what effects depend on, from the recording alone.

Columns added to the system's measurement table (one row per measurement):
``last_motion_sign`` (n, n_joints) in {−1, 0, +1} (a motion beyond 3 counts, or beyond the stream's own noise:
`ingest.context.motion_threshold`; and ``last_motion_sign_beyond_Xmrad``: of the last motion
longer than X mrad, `PLAY_RAD`), ``approach_joint_velocity`` (n, n_joints)
rad/s just before the measurement, ``time_since_start_s`` (n,), ``payload_kg`` (n,) from the
`/arm/payload` change events (else the campaign's payload schedule, else the robot model's payload), ``normal_sign`` (n,) of the
touched face (from the fixture); with each contact's recorded search command (`ingest.events`),
``search_speed_m_s`` (n,) m/s and ``search_direction`` (n, 3); when the recording has a temperature channel,
``temperature_rise_K`` (n,) since its first reading (interpolated to each measurement) and
``temperature_sensor`` (n,) the sensor's name (the first sensor; each other sensor as
``temperature_rise_K@<sensor>``).  Nothing here reads anything but what a real controller logs.
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.library.joint import PLAY_RAD, play_column
from pipeline.ingest.context import ENCODER_COUNT_RAD, last_motion_sign, motion_threshold  # noqa: F401  (re-exported)
from pipeline.ingest.temperature import TemperatureStream, rise_at


def approach_velocity(t: np.ndarray, q: np.ndarray, t_ns: np.ndarray, lead_s: float = 0.004,
                      span_s: float = 0.2, short_s: float = 0.04) -> np.ndarray:
    """Joint velocity (n, nj) rad/s just before each measurement (the window ends `lead_s`
    before it, before the arm stops after the latch).  The long window `span_s` averages the
    encoder quantisation away; where it disagrees with the short window `short_s` by more than
    10 % (a search shorter than the long window) the short one is used."""
    t_ns = np.asarray(t_ns, np.int64)
    ts = (t - t[0]) * 1e-9
    tm = (t_ns - t[0]) * 1e-9
    qc = np.ascontiguousarray(np.asarray(q, float).T)  # np.interp would copy a strided column at every call

    def over(span):
        a, b = tm - lead_s - span, tm - lead_s
        return np.stack([(np.interp(b, ts, qc[j]) - np.interp(a, ts, qc[j])) / span
                         for j in range(q.shape[1])], axis=1)

    long_, short = over(span_s), over(short_s)
    nl, ns = np.linalg.norm(long_, axis=1), np.linalg.norm(short, axis=1)
    agree = np.abs(nl - ns) <= 0.1 * np.maximum(ns, 1e-12)
    return np.where(agree[:, None], long_, short)


def payload_at(t_ns: np.ndarray, schedule: list[dict] | None, default_kg: float) -> np.ndarray:
    """Payload (kg) at each time from a schedule [{t_ns, payload_kg}] (from that time on)."""
    out = np.full(np.asarray(t_ns).size, float(default_kg))
    for step in sorted(schedule or [], key=lambda s: s["t_ns"]):
        out[np.asarray(t_ns) >= int(step["t_ns"])] = float(step["payload_kg"])
    return out


def add_temperature(table: dict, temperature: TemperatureStream, path: object = "",
                    channel: str = "/touch/contact") -> dict:
    """A copy of a table with ``temperature_rise_K`` and ``temperature_sensor`` (module docstring);
    one-line `RobocalError` when the readings do not cover a measurement."""
    t_ns = np.asarray(table["timestamp_ns"], np.int64)
    out = dict(table)
    out["temperature_rise_K"] = rise_at(temperature, t_ns, path, channel, table.get("record"))
    out["temperature_sensor"] = np.full(t_ns.size, temperature.sensor, object)
    return out


def add_context(table: dict, stream_t: np.ndarray, stream_q: np.ndarray, *, normal_sign_of: dict[str, int],
                payload_schedule: list[dict] | None, default_payload_kg: float,
                temperature: TemperatureStream | None = None, path: object = "",
                more_temperatures: tuple | list = ()) -> dict:
    """A copy of a touch table with the diagnosis columns (module docstring)."""
    t_ns = np.asarray(table["timestamp_ns"], np.int64)
    out = dict(table)
    out["last_motion_sign"] = last_motion_sign(stream_t, stream_q, t_ns, threshold_rad=motion_threshold(stream_q))
    for play in PLAY_RAD:  # the direction of the last motion that took up that much play (`library.joint.backlash_play`)
        out[play_column(play)] = last_motion_sign(stream_t, stream_q, t_ns, threshold_rad=play)
    out["approach_joint_velocity"] = approach_velocity(stream_t, stream_q, t_ns)
    out["time_since_start_s"] = (t_ns - stream_t[0]) * 1e-9
    out["payload_kg"] = payload_at(t_ns, payload_schedule, default_payload_kg)
    out["normal_sign"] = np.array([normal_sign_of[str(f)] for f in table["face"]], float)
    if temperature is not None:
        out = add_temperature(out, temperature, path)
    for ts in more_temperatures:  # several sensors: the others as temperature_rise_K@<sensor>
        out[f"temperature_rise_K@{ts.sensor}"] = rise_at(ts, t_ns, path, "/touch/contact", table.get("record"))
    return out


def from_recording(rec, stream=None):
    """(TouchModel, diagnosis table, info) of an arc-welder recording; `stream` (a
    `JointStream` already decoded, e.g. by the ingest stage) saves decoding it again."""
    from pipeline.ingest.events import misses, payload_schedule, search_commands
    from pipeline.ingest.streams import joint_stream
    from pipeline.ingest.temperature import temperature_streams
    from pipeline.models.jig import Jig
    from pipeline.recording.schemas import META_CAMPAIGN, META_FIXTURE
    from pipeline.systems import arc_welder as aw

    model, table = aw.load(rec)
    jig = Jig.from_dict(rec.meta(META_FIXTURE))
    campaign = rec.metadata.get(META_CAMPAIGN, {})
    stream = joint_stream(rec) if stream is None else stream
    temps = temperature_streams(rec)
    events = payload_schedule(rec)  # payload changes logged when they happen, else the campaign's schedule
    tab = add_context(table, stream.t_ns, stream.q, normal_sign_of={f.id: f.normal_sign for f in jig.faces},
                      payload_schedule=events if events is not None else campaign.get("payload_schedule"),
                      default_payload_kg=model.arm.payload_kg, temperature=temps[0] if temps else None,
                      path=rec.path, more_temperatures=temps[1:])
    cmd = search_commands(rec)
    if cmd is not None:
        rows = np.asarray(tab["record"], int)
        tab.update({k: v[rows] for k, v in cmd.items()})
    return model, tab, {"jig_tolerance_m": jig.tolerance_m, "system": aw.SYSTEM,
                        # the robot's declared repeatability (3σ, m) when the integrator recorded it
                        "repeatability_3sigma_m": campaign.get("robot_repeatability_3sigma_m"),
                        "payload_from": "events" if events is not None else "campaign schedule",
                        "searches_without_contact": misses(rec)}
