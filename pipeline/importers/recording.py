"""Write a URDF-robot recording: the robot description, the campaign and one message per row.

Every importer (CSV, ROS 2 bags) and `robocal simulate urdf` ends here, so a recording of
any origin reads the same way (`pipeline.systems.urdf_robot.load`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.models.urdf import RobotDescription
from pipeline.recording.scene import scene_events
from pipeline.recording.schemas import META_CAMPAIGN, META_URDF
from pipeline.recording.writer import RecordingWriter

T0_NS = 1_700_000_000_000_000_000  # a fixed epoch for tables without times (bit-identical re-imports)


def write_urdf_recording(out: str | Path, desc: RobotDescription, measure: str, campaign: dict,
                         table: dict[str, np.ndarray], labels: list[str] | None = None,
                         stream: dict[str, np.ndarray] | None = None, batch: int = 250,
                         tips: list[str] | None = None, origin: str = "") -> int:
    """Write `table` (rows: ``joint_positions`` (n, n_joints) in the chain's joint order, plus
    the type's columns: ``position`` (n,3), ``target`` (n,), ``orientation`` (n,4) xyzw,
    ``plane``/``group`` (n,) names; optional ``timestamp_ns``) to `out`.  With `stream` (``t_ns`` (T,)
    sorted, ns; ``q`` (T, n_joints) rad / m; optional drive state ``q_cmd`` rad / m, ``effort``
    N·m / N (or raw, converted as the campaign's ``effort`` declares) and ``current`` A, and logged velocities
    ``v`` rad/s / m/s, (T, n_joints), chain order) also the encoder stream, `batch` samples a message.
    `tips`: the measured links of a tree (several chains from the root; ``target`` is the tip index).
    `origin`: the header's library note (`RecordingWriter`).  Returns rows written."""
    q = np.asarray(table["joint_positions"], float)
    n = len(q)
    t = np.asarray(table.get("timestamp_ns", T0_NS + np.arange(n) * 1_000_000_000), np.int64)
    camp = {"system": "urdf", "measure": measure, "joint_names": desc.joint_names, **campaign}
    topic = f"/measure/{measure}"
    meta_urdf = {"urdf": desc.urdf, "root": desc.root, "tip": desc.tip, "source": desc.source,
                 **({"tips": list(tips)} if tips else {})}
    st = None if stream is None else (np.asarray(stream["t_ns"], np.int64), np.asarray(stream["q"], float))
    scene = sorted(scene_events({META_URDF: meta_urdf, META_CAMPAIGN: camp}, st, (t, q)), key=lambda e: e[0])
    with RecordingWriter(out, origin=origin) as w:
        w.metadata(META_URDF, meta_urdf)
        w.metadata(META_CAMPAIGN, camp)
        for ts, tp, msg in scene:  # the robot for ROS / Foxglove tools (pipeline.recording.scene)
            w.write_scene(tp, msg, ts)
        for i in range(n):
            m: dict = {"timestamp_ns": int(t[i]), "joint_positions": q[i].tolist()}
            if "position" in table:
                m["position"] = np.asarray(table["position"][i], float).tolist()
            if "target" in table:
                m["target"] = int(table["target"][i])
            if "approach" in table:
                m["approach"] = [int(v) for v in table["approach"][i]]
            if "orientation" in table:
                m["orientation"] = np.asarray(table["orientation"][i], float).tolist()
            for key in ("plane", "group"):
                if key in table:
                    m[key] = str(table[key][i])
            w.write(topic, m)
        if stream is not None:
            ts = np.asarray(stream["t_ns"], np.int64)
            for s in range(0, ts.size, batch):
                sl = slice(s, s + batch)
                w.write_batch(ts[sl], np.asarray(stream["q"])[sl], desc.joint_names,
                              q_cmd=None if stream.get("q_cmd") is None else np.asarray(stream["q_cmd"])[sl],
                              effort=None if stream.get("effort") is None else np.asarray(stream["effort"])[sl],
                              current=None if stream.get("current") is None else np.asarray(stream["current"])[sl],
                              velocity=None if stream.get("v") is None else np.asarray(stream["v"])[sl])
    return n
