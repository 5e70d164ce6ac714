"""Candidate measurement poses of the Delta + laser tracker (seed 003) for pose planning.

A candidate is an actuator configuration: nominal inverse kinematics of a platform point drawn
uniformly in the working box (the seed's grid box, `box_scale`× larger), where the tracker
reads the reflector.  The tracker readings of the table are the nominal model's predictions
(the D-optimal criterion needs only the Jacobian at the nominal parameters).
"""

from __future__ import annotations

import numpy as np

from pipeline.models import delta as dm
from pipeline.systems import delta_tracker as dt

JOINT_NAMES = ["A1", "A2", "A3"]
CENTER_M, HALF_M = np.array([0.0, 0.0, -0.750]), np.array([0.150, 0.150, 0.040])


def candidates(n: int, seed: int = 0, box_scale: float = 1.5) -> tuple[dt.TrackerModel, dict[str, np.ndarray]]:
    """(nominal measurement model, table of n candidate configurations)."""
    model = dt.TrackerModel()
    rng = np.random.default_rng(seed)
    keep: list[np.ndarray] = []
    while sum(k.shape[0] for k in keep) < n:
        p = CENTER_M + rng.uniform(-1, 1, (2 * n, 3)) * HALF_M * box_scale
        theta, ok = dm.inverse(model.delta, np.zeros(27), p)
        keep.append(theta[ok])
    theta = np.concatenate(keep)[:n]
    point = model.points(model.nominal(), {"joint_positions": theta})[0] - [0, 0, model.h_nominal]
    return model, {"joint_positions": theta, "point": point, "record": np.arange(n)}


def pose_campaign(table: dict[str, np.ndarray], idx: np.ndarray) -> dict:
    """The campaign file's system-specific part for the selected candidates (measurement: pose)."""
    return {"measurement": "pose", "joint_names": JOINT_NAMES,
            "measurements": [{"index": i, "candidate": int(j), "joints_rad": table["joint_positions"][j].tolist()}
                             for i, j in enumerate(idx)]}


def read_pose_campaign(path) -> np.ndarray:
    """Actuator angles (n, 3) rad of a delta-tracker pose campaign (one-line errors)."""
    from pipeline.plan.campaign import read_pose

    return read_pose(path, dt.SYSTEM, JOINT_NAMES)
