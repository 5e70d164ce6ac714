"""A dynamics recording from joint position / velocity / effort logs, whatever they were read from (`robocal
import csv --measure effort`, a ROS 2 bag's JointStates): the URDF, the chain, the logs as its encoder stream
(positions, logged velocities, raw efforts: `robocal.JointStateBatch` fields 4, 10, 8) and the campaign's
``effort`` declaration (how efforts become torques, which joints are fitted: `pipeline.dynamics.effort`).
Nothing prints here: what was written goes to `say` as lines."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from pipeline.importers.joint_readings import PositionSpec


@dataclass(frozen=True)
class EffortSpec:
    """The effort declaration in the command line's words: `scale` ``JOINT=K`` (N·m or N per raw unit),
    `offset` ``JOINT=C`` (N·m or N, or ``weight``: g × the mass the joint carries), `mix` ``JOINT=EXPR`` (the
    raw efforts a joint's torque combines), `joints` the comma-separated joints whose torque is fitted (''
    all), `units` ``Nm`` | ``raw`` | None (raw with a scale, else unknown); `positions`: how the position
    readings become joint angles, when they are not (motor-side encoders, a coupled wrist: `joint_readings`)."""

    scale: tuple[str, ...] = ()
    offset: tuple[str, ...] = ()
    mix: tuple[str, ...] = ()
    joints: str = ""
    units: str | None = None
    positions: PositionSpec = PositionSpec()


def write_effort_recording(out: Path, desc, logs: dict, urdf_source: str, effort: EffortSpec, extra: dict,
                           robot_id: str = "", say: Callable[[str], None] = lambda line: None) -> dict:
    """Write the recording `out` of logs {t_ns (T,), q (T, J), v (T, J) or absent, effort (T, J)} in the chain
    `desc`'s joint order with the declaration `effort` (`urdf_source` names the URDF in errors); `extra` goes
    into the campaign.  Returns the declaration written."""
    from pipeline.dynamics import effort as E
    from pipeline.importers.recording import write_urdf_recording

    joints = desc.joint_names
    sc = E.parse_pairs("--effort-scale", list(effort.scale), joints)
    off = E.parse_pairs("--effort-offset", list(effort.offset), joints, words=("weight",))
    if any(v == "weight" for v in off.values()):
        from pipeline.dynamics.rigid_body import build, subtree_weight

        rb = build(desc.urdf, joints, urdf_source)
        off = {j: subtree_weight(rb, j) if v == "weight" else v for j, v in off.items()}
    fit = [j.strip() for j in effort.joints.split(",") if j.strip()]
    doc = E.declaration(joints, sc, off, E.parse_mix(list(effort.mix), joints), fit, effort.units)
    campaign = {"effort": doc, **extra, "robot_id": robot_id or desc.name}
    if doc["unit"] == "unknown":
        say("warning: no --effort-scale or --effort-units: the effort units are recorded as unknown (robocal run "
            "will refuse to fit torques)")
    table = {"joint_positions": np.zeros((0, len(joints))), "timestamp_ns": np.zeros(0, np.int64)}
    write_urdf_recording(out, desc, "effort", campaign, table,
                         stream={"t_ns": logs["t_ns"], "q": logs["q"], "v": logs.get("v"), "effort": logs["effort"]})
    say(f"imported {len(logs['t_ns'])} samples of {len(joints)} joints' position"
        f"{', velocity' if logs.get('v') is not None else ''} and effort ({desc.root} → {desc.tip}; torque "
        f"fitted on {', '.join(doc['fit_joints'])}) into {out}")
    return doc
