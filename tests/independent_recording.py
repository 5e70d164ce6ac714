"""The independent generator's own MCAP writer: a campaign of `independent_touch` as a
controller would log it, following `schemas/` only (the schema files are registered as they are;
no code of `pipeline.recording`).

Channels: `/robot/joint_state` (batches of 250 samples), `/touch/contact` with each contact's
`search` command (speed, direction into the face, stand-off, target), `/arm/payload` at each
payload change as it happened, `/touch/miss` (a search that faulted, when asked for), `/arm/temperature`
(several sensors, when given); metadata:
the robot model, the fixture and the campaign (with the *programmed* payload schedule, which the
operator may not have followed: `independent_touch.run(payload_late=…)`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from mcap.writer import Writer

SCHEMAS = Path(__file__).resolve().parents[1] / "schemas"
AXES = "xyz"


def _body(o: dict) -> bytes:
    return json.dumps(o, separators=(",", ":"), allow_nan=False).encode()


def write_recording(path: Path, campaign, robot_model: dict, fixture: dict, *, events: bool = True,
                    search: bool = True, faulted: list[int] = (), repeatability_3sigma_m: float = 1e-4,
                    standoff_m: float = 0.04, temperatures: dict | None = None) -> None:
    """Write `campaign` (`independent_touch.Campaign`) to `path`.  `events`: log `/arm/payload`;
    `search`: each contact's search command; `faulted`: contacts whose search the controller aborted
    (logged on `/touch/miss` with reason `fault` instead of a contact); `temperatures`: {sensor: K as a
    function of the time since the stream's start (s)}, read once a second on `/arm/temperature`."""
    tab = campaign.contacts
    msgs: list[tuple[str, dict]] = []
    t, q = campaign.stream_t_ns, campaign.stream_q
    for s in range(0, t.size, 250):
        msgs.append(("/robot/joint_state", {"timestamp_ns": int(t[s]), "timestamps_ns": [int(v) for v in t[s:s + 250]],
                                            "joint_names": [f"J{j + 1}" for j in range(q.shape[1])],
                                            "positions": np.round(q[s:s + 250], 9).tolist()}))
    for i in range(len(tab["timestamp_ns"])):
        t_i, q_i = int(tab["timestamp_ns"][i]), [float(v) for v in tab["joint_positions"][i]]
        if i in faulted:
            msgs.append(("/touch/miss", {"timestamp_ns": t_i, "joint_positions": q_i, "face": str(tab["face"][i]),
                                         "campaign_index": i, "reason": "fault", "fault_code": "E-STOP 112"}))
            continue
        m = {"timestamp_ns": t_i, "joint_positions": q_i, "face": str(tab["face"][i]),
             "axis": AXES[int(tab["axis"][i])], "coordinate": float(tab["coordinate"][i])}
        if search:
            m["search"] = {"speed_m_s": float(campaign.search_speed[i]),
                           "direction": [float(v) for v in campaign.search_direction[i]], "standoff_m": standoff_m}
        msgs.append(("/touch/contact", m))
    if events:
        msgs += [("/arm/payload", {"timestamp_ns": int(tc), "payload_kg": float(kg), "tool": "torch"})
                 for tc, kg in campaign.payload_changes]
    t_read = np.arange(t[0], t[-1] + 1, 1_000_000_000, dtype=np.int64)
    for sensor, kelvin in (temperatures or {}).items():
        k = kelvin((t_read - t[0]) * 1e-9)
        msgs += [("/arm/temperature", {"timestamp_ns": int(tr), "sensor": sensor, "temperature_k": round(float(v), 4)})
                 for tr, v in zip(t_read, k)]
    msgs.sort(key=lambda tm: tm[1]["timestamp_ns"])
    stems = {"/robot/joint_state": "joint_state", "/touch/contact": "touch_contact", "/touch/miss": "touch_miss",
             "/arm/payload": "payload", "/arm/temperature": "temperature"}
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="robocal", library="independent_touch")
        for name, value in (("robocal.robot_model", robot_model), ("robocal.fixture", fixture),
                            ("robocal.campaign", {"system": "arc-welder",
                                                  "payload_schedule": campaign.planned_schedule,
                                                  "robot_repeatability_3sigma_m": repeatability_3sigma_m})):
            w.add_metadata(name, {"json": json.dumps(value)})
        chan, seq = {}, {}
        for topic, m in msgs:
            if topic not in chan:
                sch = json.loads((SCHEMAS / f"{stems[topic]}.schema.json").read_text())
                sid = w.register_schema(name=sch["title"], encoding="jsonschema",
                                        data=(SCHEMAS / f"{stems[topic]}.schema.json").read_bytes())
                chan[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
                seq[topic] = 0
            seq[topic] += 1
            w.add_message(chan[topic], log_time=m["timestamp_ns"], data=_body(m), publish_time=m["timestamp_ns"],
                          sequence=seq[topic])
        w.finish()
