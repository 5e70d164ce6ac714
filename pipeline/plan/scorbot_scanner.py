"""Pose planning for the laser-stripe scanner on the SCORBOT (seed 001).

A candidate is a pose whose stripe lies on a grid line of the printed target with the campaign's
number of crossings in the image — drawn as the paper's operator does (random stand-off, aim, tilt
and roll, then the stripe servoed onto the nearest grid line), here on the NOMINAL arm and scanner.
All of a pose's corner rows are measured together, so the D-optimal choice is over poses: each
candidate contributes the stacked Jacobian of its crossings.  The executable campaign gives each
chosen pose's joints and its grid line; `robocal simulate scorbot-scanner --campaign` servoes the
true arm onto that line from those joints (`simulate/scanner_servo.py`).
"""

from __future__ import annotations

import numpy as np

from pipeline.identify.identifiability import analyse
from pipeline.plan.doptimal import Selection, select
from pipeline.simulate import scorbot_scanner as sim
from pipeline.systems import scorbot_scanner as sc

JOINT_NAMES = ["J1", "J2", "J3", "J4", "J5"]
IMAGE_H = sc.IMAGE_SIZE_PX[1]
BATCH = 50  # poses per candidate batch: the printed grid has ~100 distinct lines in reach


def candidates(n: int, seed: int = 0, corners: int = 5) -> tuple[sc.ScannerModel, dict[str, np.ndarray]]:
    """(nominal model, table of n candidate poses × `corners` crossings, noise-free, at nominal)."""
    arm = sc.nominal_arm()
    parts, done, batch = [], 0, 0
    while done < n:  # batches of distinct grid lines (a campaign never repeats a line; candidates may)
        k = min(BATCH, n - done)
        camp = sim.Campaign(poses=k, corners=corners, seed=seed * 10_007 + batch)
        _, t = sim.simulate_in_memory(arm, arm, sc.nominal_scanner(), camp, sim.Noise(scale=0.0))
        t["pose"] = t["pose"] + done
        parts.append(t)
        done, batch = done + k, batch + 1
    table = {key: np.concatenate([t[key] for t in parts]) for key in ("joint_positions", "pixel", "corner", "pose")}
    table["record"] = table["pose"].copy()
    table["corner_index"] = _corner_index(table["corner"])
    return sc.ScannerModel(), table


def _corner_index(corner: np.ndarray) -> np.ndarray:
    P = sim.Pattern().corners()
    d = np.linalg.norm(corner[:, None, :] - P[None], axis=2)
    return np.argmin(d, axis=1)


def plan_poses(model: sc.ScannerModel, table: dict[str, np.ndarray], m: int) -> tuple[Selection, np.ndarray]:
    """D-optimal choice of m poses (log det of the free parameters' information; rows grouped by
    pose).  Returns (selection over poses, free-parameter mask)."""
    J = model.jacobian(model.nominal(), table)  # (rows, 3, P)
    ident = analyse(J.reshape(-1, J.shape[-1]), model.parameter_names(), priority=model.priority())
    pose = np.asarray(table["pose"])
    counts = np.bincount(pose)
    if np.any(np.diff(pose) < 0) or np.any(counts != counts[0]):
        raise ValueError("candidate rows must be grouped by pose with equal crossings per pose")
    A = J[:, :, ident.free].reshape(counts.size, -1, int(ident.free.sum()))
    return select(A, m), ident.free


def pose_campaign(table: dict[str, np.ndarray], poses: np.ndarray) -> dict:
    """The campaign file's system-specific part: per chosen pose its joints (rad), grid line and the
    image row (px) where the planning model sees that line (the stand-off the operator keeps)."""
    ids = sim.Pattern().ids()
    out = []
    for i, p in enumerate(poses):
        rows = np.flatnonzero(table["pose"] == p)
        out.append({"index": i, "candidate": int(p), "joints_rad": table["joint_positions"][rows[0]].tolist(),
                    "corner_ids": [ids[j] for j in table["corner_index"][rows]],
                    "stripe_row_px": float(np.mean(table["pixel"][rows, 1]))})
    return {"measurement": "pose", "joint_names": JOINT_NAMES, "measurements": out}


def read_campaign(path) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """(joints rad, grid-line corner indices, image row px) per planned pose of a scanner campaign
    (one-line errors)."""
    from pipeline.errors import RobocalError
    from pipeline.plan.campaign import load_document, read_pose

    q = read_pose(path, sc.SYSTEM, JOINT_NAMES)
    ids = {c: i for i, c in enumerate(sim.Pattern().ids())}
    out = []
    for k, m in enumerate(load_document(path)["measurements"]):
        line = m.get("corner_ids")
        if not isinstance(line, list) or len(line) < 2 or any(c not in ids for c in line):
            raise RobocalError(f"{path}: measurement {m['index']}: corner_ids must name ≥ 2 corners of the "
                               f"pattern (e.g. {sim.Pattern().ids()[0]})")
        row = m.get("stripe_row_px", IMAGE_H / 2)
        if not isinstance(row, (int, float)) or not 0 <= row <= IMAGE_H:
            raise RobocalError(f"{path}: measurement {m['index']}: stripe_row_px must be a row of the image (0–{IMAGE_H})")
        out.append((q[k], np.array([ids[c] for c in line]), float(row)))
    return out
