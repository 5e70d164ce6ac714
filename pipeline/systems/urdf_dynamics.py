"""A URDF robot's dynamics recording (campaign ``measure: effort``): the model and the sample table.

The measurements are the encoder stream's samples themselves (`/robot/joint_state`: positions, logged
velocities, efforts), with the campaign's ``effort`` declaration turning efforts into joint torques
(`pipeline.dynamics.effort`).  `load` gives the `DynamicsModel` (what the stages need to identify: the
URDF, the recorded joints, the declaration) and the table, one row per sample: ``timestamp_ns``,
``joint_positions`` (T, J) rad / m, ``joint_efforts`` (T, J) as logged, ``joint_torques`` (T, J) N·m / N,
optionally ``joint_velocities`` (T, J) rad/s, and ``record`` (the sample index).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import RobocalError, where
from pipeline.recording.schemas import META_CAMPAIGN, META_URDF

FAMILY = "dynamics"


@dataclass(frozen=True)
class DynamicsModel:
    """What a dynamics recording declares: URDF text, root, tip, the recorded joints (chain order), the
    effort declaration (checked), the recording's path for messages, and how its position readings became
    joint angles (campaign ``positions``, `pipeline.importers.joint_readings`; None: they were)."""

    urdf: str
    root: str
    tip: str
    joints: tuple[str, ...]
    effort: dict
    source: str
    system: str = "urdf"
    family: str = FAMILY
    positions: dict | None = None

    @property
    def fit_mask(self) -> np.ndarray:
        return np.isin(self.joints, self.effort["fit_joints"])

    @property
    def motors(self) -> tuple:
        """The motors that turn several joints (`joint_readings.coupled_motors`): their own friction terms."""
        from pipeline.importers.joint_readings import coupled_motors

        return coupled_motors(self.positions, list(self.joints))

    def rigid_body(self):
        from pipeline.dynamics.rigid_body import build

        return build(self.urdf, list(self.joints), f"{self.source}: metadata robocal.urdf")


def positions_doc(doc, joints: list[str], where_: str) -> dict | None:
    """The campaign's ``positions`` declaration checked (joint names → finite numbers), or None."""
    if doc is None:
        return None
    ok = isinstance(doc, dict) and all(isinstance(doc.get(k, {}), dict) for k in ("scale", "offset", "mix")) \
        and all(isinstance(t, dict) for t in (doc.get("mix") or {}).values())
    vals = [(j, x) for k in ("scale", "offset") for j, x in (doc.get(k) or {}).items()] + \
        [(k, f) for t in (doc.get("mix") or {}).values() if isinstance(t, dict) for k, f in t.items()] if ok else []
    if not ok or any(j not in joints or isinstance(x, bool) or not isinstance(x, (int, float)) or not np.isfinite(x)
                     for j, x in vals) or any(j not in joints for j in (doc.get("mix") or {})):
        raise RobocalError(f"{where_}: metadata robocal.campaign: positions must map joints of the chain to finite "
                           "numbers (scale, offset) and joints to {joint: factor} (mix)")
    from pipeline.importers.joint_readings import check_invertible

    check_invertible(doc, joints, f"{where_}: metadata robocal.campaign: positions")
    return doc


def is_dynamics(model) -> bool:
    return getattr(model, "family", None) == FAMILY


def load(rec) -> tuple[DynamicsModel, dict[str, np.ndarray]]:
    from pipeline.dynamics import effort as E
    from pipeline.ingest.streams import JOINT_STATE, joint_stream
    from pipeline.models import urdf

    meta, campaign = rec.meta(META_URDF), rec.meta(META_CAMPAIGN)
    if not isinstance(meta, dict) or not all(isinstance(meta.get(k), str) for k in ("urdf", "root", "tip")):
        raise RobocalError(f"{rec.path}: metadata robocal.urdf must hold strings urdf, root and tip")
    desc = urdf.parse(meta["urdf"], meta["root"], meta["tip"], source=f"{rec.path}: metadata robocal.urdf")
    joints = desc.joint_names
    doc = E.check(campaign.get("effort"), joints, f"{rec.path}: metadata robocal.campaign")
    s = joint_stream(rec)
    missing = [j for j in joints if j not in s.names]
    if missing:
        raise RobocalError(f"{where(rec.path, JOINT_STATE)}: lacks chain joint(s) {', '.join(missing)}")
    if s.effort is None:
        raise RobocalError(f"{where(rec.path, JOINT_STATE)}: no efforts (robocal.JointStateBatch field 8): a "
                           "dynamics recording needs the drives' efforts")
    if len(s) < 50:
        raise RobocalError(f"{where(rec.path, JOINT_STATE)}: {len(s)} samples, too few to identify dynamics")
    order = np.argsort(s.t_ns, kind="stable")
    if (np.diff(s.t_ns) <= 0).any():
        i = int(np.flatnonzero(np.diff(s.t_ns) <= 0)[0]) + 1
        raise RobocalError(f"{where(rec.path, JOINT_STATE, int(s.message_index[i]))}: sample {i}: time does not "
                           "increase: dynamics needs strictly increasing sample times")
    cols = np.array([s.names.index(j) for j in joints])
    model = DynamicsModel(meta["urdf"], meta["root"], meta["tip"], tuple(joints), doc, str(rec.path),
                          positions=positions_doc(campaign.get("positions"), joints, str(rec.path)))
    table = {"timestamp_ns": s.t_ns[order], "joint_positions": s.q[order][:, cols],
             "joint_efforts": s.effort[order][:, cols], "record": np.arange(len(s), dtype=np.int64)}
    if doc["unit"] != "unknown":
        table["joint_torques"] = E.to_torque(table["joint_efforts"], doc, joints)
    if s.velocity is not None:
        table["joint_velocities"] = s.velocity[order][:, cols]
    return model, table
