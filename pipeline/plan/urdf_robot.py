"""Pose candidates for a URDF robot measured by points or poses: random joint configurations
within the limits (continuous joints within ±π), as measurement tables of the recording's model.

For point and pose measurements the Jacobian does not depend on the measured values at the
planning point (the prediction stands in for the measurement), so a candidate is its joint
configuration; plane and coincidence campaigns need the fixture and are planned from a recording's
own configurations (`from_recording`).
"""

from __future__ import annotations

import numpy as np

from pipeline.identify.model import Table
from pipeline.measurements.composed import Composed


def configurations(kin, n: int, seed: int = 0) -> np.ndarray:
    """n joint vectors (n, n_joints) uniform within the limits (±π where a joint has none)."""
    rng = np.random.default_rng(seed)
    lo = np.where(np.isfinite(kin.lower), kin.lower, -np.pi)
    hi = np.where(np.isfinite(kin.upper), kin.upper, np.pi)
    return rng.uniform(lo, hi, (n, len(lo)))


def table_at(model: Composed, x: np.ndarray, q: np.ndarray) -> Table:
    """The measurement table the model would see at configurations q with parameters x (noise-free)."""
    from scipy.spatial.transform import Rotation

    p, _, R, _ = model.tool(x, q)
    t: dict[str, np.ndarray] = {"joint_positions": q, "record": np.arange(len(q))}
    if model.residual_dim == 3 and hasattr(model, "n_targets"):
        t |= {"position": p, "target": np.zeros(len(q), int)}
    elif model.residual_dim == 6:
        t |= {"position": p, "orientation": Rotation.from_matrix(R).as_quat()}
    else:
        raise ValueError("URDF planning from random configurations needs point or pose measurements")
    return t


def candidates_for(model: Composed, n: int, seed: int = 0, x: np.ndarray | None = None) -> Table:
    """n random candidate measurements of a point or pose model (at x, default nominal)."""
    x = model.nominal() if x is None else x
    return table_at(model, x, configurations(model.kin, n, seed))


def pose_campaign(desc, measure: str, q: np.ndarray, idx: np.ndarray, urdf_path: str) -> dict:
    """The campaign file's robot-specific part: the chosen joint configurations (rad) by URDF joint
    name, measured there with `measure` (point or pose) — schemas/campaign.schema.json."""
    return {"measurement": "pose", "instrument": measure, "joint_names": list(desc.joint_names),
            "urdf": {"path": urdf_path, "root": desc.root, "tip": desc.tip, "robot": desc.name},
            "measurements": [{"index": i, "candidate": int(j), "joints_rad": q[j].tolist()}
                             for i, j in enumerate(idx)]}
