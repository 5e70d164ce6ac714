"""What a recording carries for ROS / Foxglove tools: the robot's frames and its description.

Every recording robocal writes (simulations, CSV and ROS 2 imports, acquisitions — the last at close,
`RecordingWriter(scene=True)`) gets, beside its own channels:

- ``/tf``: ``foxglove.FrameTransforms`` (JSON encoding, the JSON Schema of Foxglove's message
  schema `schemas/foxglove_frame_transforms.schema.json`), one message per posture of the campaign
  (the encoder stream at `RATE_HZ`, and every measurement posture): the chain's transforms parent
  link → child link (joint origin · joint motion), ``robocal_instrument`` → the root link and the
  tip link → ``robocal_tool``.  These are the *nominal* robot's (the recording is written before
  any calibration): instrument → root is the robot model's nominal base (identity for a URDF
  robot, whose registration the calibration estimates), the tool frame the model's nominal tool.
  Translations m, rotations unit quaternions (x, y, z, w); timestamps {sec, nsec} since the epoch.
- ``/robot_description``: one ``std_msgs/msg/String`` message (JSON ``{"data": <URDF>}``), the
  robot's URDF as ROS publishes it, and the same text as the MCAP attachment
  ``robot_description.urdf`` — Foxglove's 3-D panel draws the robot from it (URDF layer, source
  "topic") and moves it with ``/tf``.

Seed 000's D-H arm (metadata ``robocal.robot_model``) is written as a URDF by
`pipeline.models.dh_export.to_urdf`; a Delta (a closed chain) gets the tree a viewer needs and its
transforms from `pipeline.recording.delta_scene`.
robocal's own reader ignores both channels (they are not robocal channels, see `CHANNELS`).
"""

from __future__ import annotations

import json

import numpy as np

from pipeline.recording.schemas import META_ROBOT, META_URDF, schema_bytes

TF_TOPIC = "/tf"
DESCRIPTION_TOPIC = "/robot_description"
ATTACHMENT = "robot_description.urdf"
INSTRUMENT_FRAME = "robocal_instrument"
TOOL_FRAME = "robocal_tool"
RATE_HZ = 5.0

# topic -> (schema name Foxglove / ROS tools recognise, schema file stem)
SCENE_CHANNELS: dict[str, tuple[str, str]] = {
    TF_TOPIC: ("foxglove.FrameTransforms", "foxglove_frame_transforms"),
    DESCRIPTION_TOPIC: ("std_msgs/msg/String", "std_msgs_string"),
}


def scene_schema(topic: str) -> tuple[str, bytes]:
    """(schema name, JSON Schema bytes) of a scene channel."""
    name, stem = SCENE_CHANNELS[topic]
    return name, schema_bytes(stem)


def description(metadata: dict):
    """(UrdfArm of the nominal robot, URDF text) from a recording's metadata, or None."""
    from pipeline.models import urdf
    from pipeline.models.urdf_arm import UrdfArm

    meta = metadata.get(META_URDF)
    if isinstance(meta, dict) and all(isinstance(meta.get(k), str) for k in ("urdf", "root", "tip")):
        return UrdfArm(urdf.parse(meta["urdf"], meta["root"], meta["tip"])), meta["urdf"]
    robot = metadata.get(META_ROBOT)
    if isinstance(robot, dict):
        from pipeline.models.dh_export import to_urdf
        from pipeline.models.serial_arm import SerialArm

        try:
            text = to_urdf(SerialArm.from_dict(robot))
        except (KeyError, TypeError, ValueError):
            return None
        return UrdfArm(urdf.parse(text, "jig", "tool")), text
    return None


def _stamp(t_ns: int) -> dict:
    return {"sec": int(t_ns) // 1_000_000_000, "nsec": int(t_ns) % 1_000_000_000}


def _quat(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).as_quat()  # x, y, z, w


def frame_messages(arm, q: np.ndarray, t_ns: np.ndarray) -> list[dict]:
    """One ``foxglove.FrameTransforms`` message body per posture (q (N, n_joints) rad / m, t_ns (N,))."""
    pairs, rel = chain_transforms(arm, q)
    quats = _quat(rel[..., :3, :3].reshape(-1, 3, 3)).reshape(rel.shape[0], -1, 4)
    out = []
    for i, t in enumerate(np.asarray(t_ns, np.int64)):
        stamp = _stamp(t)
        out.append({"transforms": [
            {"timestamp": stamp, "parent_frame_id": a, "child_frame_id": b,
             "translation": dict(zip("xyz", map(float, rel[i, k, :3, 3]))),
             "rotation": dict(zip("xyzw", map(float, quats[i, k])))} for k, (a, b) in enumerate(pairs)]})
    return out


def chain_transforms(arm, q: np.ndarray, x: np.ndarray | None = None) -> tuple[list[tuple[str, str]], np.ndarray]:
    """(parent → child frame pairs, their transforms (N, K, 4, 4), m) of a `UrdfArm` at parameters x
    (default its own) and postures q (N, n_joints): root → ``robocal_instrument`` (the inverse of the
    instrument → root registration), each joint's parent link → child link, tip → ``robocal_tool``."""
    q = np.atleast_2d(np.asarray(q, float))
    names, F = arm.link_frames(arm.vector() if x is None else np.asarray(x, float), q)
    names = names[:-1] + [TOOL_FRAME]
    rel = np.concatenate([np.linalg.inv(F[:, :1]), np.linalg.inv(F[:, :-1]) @ F[:, 1:]], axis=1)
    return [(names[0], INSTRUMENT_FRAME)] + list(zip(names[:-1], names[1:])), rel


def postures(stream: tuple[np.ndarray, np.ndarray] | None, measured: tuple[np.ndarray, np.ndarray] | None,
             rate_hz: float = RATE_HZ) -> tuple[np.ndarray, np.ndarray]:
    """Postures to publish, time-sorted: the encoder stream (t_ns, q) at about `rate_hz` plus every
    measurement posture (t_ns, q)."""
    ts, qs = [], []
    if stream is not None and len(stream[0]):
        t = np.asarray(stream[0], np.int64)
        bins = (t - t[0]) // int(1e9 / rate_hz)
        idx = np.flatnonzero(np.r_[True, np.diff(bins) > 0])  # the first sample of each period
        ts.append(t[idx])
        qs.append(np.asarray(stream[1], float)[idx])
    if measured is not None and len(measured[0]):
        ts.append(np.asarray(measured[0], np.int64))
        qs.append(np.atleast_2d(np.asarray(measured[1], float)))
    if not ts:
        return np.zeros(0, np.int64), np.zeros((0, 0))
    t, q = np.concatenate(ts), np.concatenate(qs)
    order = np.argsort(t, kind="stable")
    return t[order], q[order]


def tree_description(metadata: dict):
    """The `UrdfTree` of a recording measured at several tips or with coupled joints, or None."""
    from pipeline.models import urdf
    from pipeline.models.urdf_tree import UrdfTree
    from pipeline.recording.schemas import META_CAMPAIGN

    meta, camp = metadata.get(META_URDF), metadata.get(META_CAMPAIGN) or {}
    if not (isinstance(meta, dict) and all(isinstance(meta.get(k), str) for k in ("urdf", "root", "tip"))):
        return None
    tips = meta.get("tips") or [meta["tip"]]
    coupled = camp.get("coupled") or {}
    if len(tips) < 2 and not coupled and not urdf.mimic_couplings(meta["urdf"]):
        return None
    descs = tuple(urdf.parse(meta["urdf"], meta["root"], t, allow_mimic=True) for t in tips)
    movable = {j.name for d in descs for j in d.movable}
    cp = {c: v for c, v in urdf.mimic_couplings(meta["urdf"]).items() if c in movable}
    cp |= {c: (dict(v["terms"]), float(v.get("offset", 0.0))) for c, v in coupled.items()}
    return UrdfTree(descs, coupled=tuple((c, tuple(sorted(t.items())), o) for c, (t, o) in sorted(cp.items())))


def tree_messages(tree, q: np.ndarray, t_ns: np.ndarray) -> list[dict]:
    """`frame_messages` of a tree: every tip's chain from the full joint matrix, each link once, one
    tool frame per tip (``robocal_tool_<tip>``, as in the calibrated URDF)."""
    from pipeline.models.urdf_arm import UrdfArm

    qf = tree.expand(q)
    col = {j.name: i for i, j in enumerate(tree.all_joints)}
    per_tip = [frame_messages(UrdfArm(d), qf[:, [col[j.name] for j in d.movable]], t_ns) for d in tree.descs]
    out = []
    for i in range(len(np.atleast_1d(t_ns))):
        seen, transforms = set(), []
        for d, msgs in zip(tree.descs, per_tip):
            for tr in msgs[i]["transforms"]:
                if tr["child_frame_id"] == TOOL_FRAME:
                    tr = {**tr, "child_frame_id": f"{TOOL_FRAME}_{d.tip}"}
                if tr["child_frame_id"] not in seen:
                    seen.add(tr["child_frame_id"])
                    transforms.append(tr)
        out.append({"transforms": transforms})
    return out


def scene_events(metadata: dict, stream=None, measured=None) -> list[tuple[int, str, dict]]:
    """(log time ns, topic, message) of the scene channels for a recording with this metadata,
    encoder stream (t_ns, q) and measurement postures (t_ns, q); [] for robots without a chain."""
    t, q = postures(stream, measured)
    tree = tree_description(metadata)
    if tree is not None and t.size and q.shape[1] == tree.n_joints:
        events = [(int(t[0]), DESCRIPTION_TOPIC, {"data": tree.urdf})]
        return events + [(int(ti), TF_TOPIC, m) for ti, m in zip(t, tree_messages(tree, q, t))]
    robot = metadata.get(META_ROBOT)
    if isinstance(robot, dict) and robot.get("kind") == "delta":
        return _delta_events(metadata, t, q)
    found = description(metadata) if tree is None else None
    if found is None or t.size == 0:
        return []
    arm, text = found
    if q.shape[1] != arm.n_joints:
        return []
    events = [(int(t[0]), DESCRIPTION_TOPIC, {"data": text})]
    return events + [(int(ti), TF_TOPIC, m) for ti, m in zip(t, frame_messages(arm, q, t))]


def _delta_events(metadata: dict, t: np.ndarray, q: np.ndarray) -> list[tuple[int, str, dict]]:
    from pipeline.models.delta import Delta
    from pipeline.recording import delta_scene
    from pipeline.recording.schemas import META_FIXTURE

    try:
        delta = Delta.from_dict(metadata[META_ROBOT])
    except (KeyError, TypeError, ValueError):
        return []
    if t.size == 0 or q.shape[1] != delta.n_legs:
        return []
    h = (metadata.get(META_FIXTURE) or {}).get("reflector_offset_m", 0.0)
    h = float(h) if isinstance(h, (int, float)) and np.isfinite(h) else 0.0
    events = [(int(t[0]), DESCRIPTION_TOPIC, {"data": delta_scene.urdf_text(delta, h)})]
    return events + [(int(ti), TF_TOPIC, m) for ti, m in zip(t, delta_scene.frame_messages(delta, q, t, h))]


def encode(msg: dict) -> bytes:
    return json.dumps(msg, separators=(",", ":")).encode()
