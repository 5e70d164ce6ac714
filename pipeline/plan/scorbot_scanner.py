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
from pipeline.plan.doptimal import Selection, SelectionError, select
from pipeline.simulate import scorbot_scanner as sim
from pipeline.simulate.scanner_operator import OperatorPose, aim_box, camera_at
from pipeline.systems import scorbot_scanner as sc

JOINT_NAMES = ["J1", "J2", "J3", "J4", "J5"]
IMAGE_H = sc.IMAGE_SIZE_PX[1]
BATCH = 50  # poses per candidate batch: the printed grid has ~100 distinct lines in reach
STANDOFF_M = (0.20, 0.45)  # first-stage starting stand-offs (the operator backs off from there)
LIMIT_MARGIN_RAD = 0.15  # first-stage approach joints this far inside every limit (the true arm and hand-eye differ)


def candidates(n: int, seed: int = 0, corners: int = 5,
               scanner: np.ndarray | None = None) -> tuple[sc.ScannerModel, dict[str, np.ndarray]]:
    """(model, table of n candidate poses × `corners` crossings, noise-free) drawn by the paper's
    operator on the nominal arm with `scanner` (14,) — the nominal one (middle of Table 2's bounds)
    unless given (a calibrated estimate: `after`)."""
    arm = sc.nominal_arm()
    s = sc.nominal_scanner() if scanner is None else np.asarray(scanner, float)
    parts, done, batch = [], 0, 0
    while done < n:  # batches of distinct grid lines (a campaign never repeats a line; candidates may)
        k = min(BATCH, n - done)
        camp = sim.Campaign(poses=k, corners=corners, seed=seed * 10_007 + batch)
        _, t = sim.simulate_in_memory(arm, arm, s, camp, sim.Noise(scale=0.0))
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


def read_campaign(path) -> list:
    """Per planned pose of a scanner campaign, in order: (joints rad, grid-line corner indices,
    image row px), or an `OperatorPose` for a first stage's pose (one-line errors)."""
    from pipeline.errors import RobocalError
    from pipeline.plan.campaign import load_document, read_pose

    q = read_pose(path, sc.SYSTEM, JOINT_NAMES)
    ids = {c: i for i, c in enumerate(sim.Pattern().ids())}
    out = []
    for k, m in enumerate(load_document(path)["measurements"]):
        if "operator" in m:
            o = m["operator"]
            out.append(OperatorPose(tuple(o["aim_m"]), float(o["standoff_m"]), float(o["tilt_rad"]), float(o["roll_rad"])))
            continue
        line = m.get("corner_ids")
        if not isinstance(line, list) or len(line) < 2 or any(c not in ids for c in line):
            raise RobocalError(f"{path}: measurement {m['index']}: corner_ids must name ≥ 2 corners of the "
                               f"pattern (e.g. {sim.Pattern().ids()[0]}), or operator a first-stage pose")
        row = m.get("stripe_row_px", IMAGE_H / 2)
        if not isinstance(row, (int, float)) or not 0 <= row <= IMAGE_H:
            raise RobocalError(f"{path}: measurement {m['index']}: stripe_row_px must be a row of the image (0–{IMAGE_H})")
        out.append((q[k], np.array([ids[c] for c in line]), float(row)))
    return out


def first_stage(m: int, n: int = 400, seed: int = 0) -> dict:
    """A first stage of m operator poses (`OperatorPose`), spread by a greedy maximin design over n
    random ones in (aim x, aim y, stand-off, tilt, roll), each scaled to [0, 1]: before any
    calibration the scanner is known only within Table 2's bounds (its pixel pitch to 8×, its laser
    baseline to 80×), so no model can say which crossings a pose will see — the stripe is jogged
    onto the grid line nearest to it in the true image, as the paper's operator does.  Approach
    joints from the nominal arm and hand-eye (rad), kept `LIMIT_MARGIN_RAD` inside the joint limits."""
    rng = np.random.default_rng(seed)
    lo, hi = aim_box(sim.Pattern())
    max_tilt = sim.Campaign().max_tilt_rad
    U = rng.uniform(0, 1, (n, 5))  # aim x, aim y, stand-off, tilt, roll
    geo = np.column_stack([lo + U[:, :2] * (hi - lo), STANDOFF_M[0] + U[:, 2] * np.ptp(STANDOFF_M),
                           (2 * U[:, 3] - 1) * max_tilt, (2 * U[:, 4] - 1) * np.pi / 2])
    arm = sc.nominal_arm()
    xa, s = arm.vector(), sc.nominal_scanner()
    lo_q, hi_q = arm.lower + LIMIT_MARGIN_RAD, arm.upper - LIMIT_MARGIN_RAD
    chosen, joints = [], []
    dist = np.full(n, 1e9)  # distance to the nearest chosen pose in the unit design cube
    dist[np.argmin(np.linalg.norm(U - 0.5, axis=1))] = 2e9  # start from the centre of the design space
    avail = np.ones(n, bool)
    while len(chosen) < m and avail.any():
        i = int(np.argmax(np.where(avail, dist, -1.0)))
        avail[i] = False
        aim = np.append(geo[i, :2], sim.Pattern().origin[2])
        q = camera_at(xa, s, aim, geo[i, 2], geo[i, 3], geo[i, 4])
        if q is None or np.any(q < lo_q) or np.any(q > hi_q):
            continue
        chosen.append(i)
        joints.append(q)
        dist = np.minimum(dist, np.linalg.norm(U - U[i], axis=1))
    if len(chosen) < m:
        raise SelectionError(f"only {len(chosen)} of {m} first-stage poses are reachable by the nominal arm")
    out = [{"index": k, "candidate": int(i), "joints_rad": q.tolist(),
            "operator": {"aim_m": [float(geo[i, 0]), float(geo[i, 1]), float(sim.Pattern().origin[2])],
                         "standoff_m": float(geo[i, 2]), "tilt_rad": float(geo[i, 3]), "roll_rad": float(geo[i, 4])}}
           for k, (i, q) in enumerate(zip(chosen, joints))]
    return {"measurement": "pose", "joint_names": JOINT_NAMES, "measurements": out,
            "criterion": "first stage: greedy maximin over (aim x, aim y, stand-off, tilt, roll), each scaled to [0, 1]"}


def after(run_dir, m: int, n: int = 200, seed: int = 0, corners: int = 5) -> dict:
    """The next stage planned on the run of the stages so far (`robocal run REC --out RUN`): the
    scanner refitted from its crossings, n candidate poses drawn on that estimate, and the m of them
    that minimise the mean predicted squared 3-D error over the candidates' crossings given what the
    earlier stages measured (I-optimal, `plan/ioptimal.py`: prior information = the earlier
    crossings' Fisher information at the estimate)."""
    from pathlib import Path

    from pipeline.errors import RobocalError
    from pipeline.ingest.tables import model_columns
    from pipeline.stages.ingest import read_measurements, recording_info

    info = recording_info(Path(run_dir))
    if info.get("system") != sc.SYSTEM:
        raise RobocalError(f"{run_dir}: is a {info.get('system')} run, not {sc.SYSTEM}")
    return next_stage(model_columns(read_measurements(Path(run_dir))), m, n, seed, corners)


def next_stage(done: dict[str, np.ndarray], m: int, n: int = 200, seed: int = 0, corners: int = 5) -> dict:
    """`after` on the crossings measured so far (a scanner table)."""
    from pipeline.identify.least_squares import fit
    from pipeline.plan import ioptimal

    from pipeline.errors import RobocalError

    if np.unique(done["pose"]).size < 3:
        raise RobocalError(f"only {np.unique(done['pose']).size} scanner pose(s) measured so far: a next stage is "
                           "planned on a calibration of at least 3 (take more first-stage poses)")
    model = sc.ScannerModel()
    est = fit(model, done)
    try:
        model, table = candidates(n, seed, corners, scanner=est.x[:len(sc.nominal_scanner())])
    except RuntimeError:
        raise RobocalError("the scanner estimated from the stages so far cannot place the paper's poses (its stripe "
                           "misses the pattern): take more first-stage poses") from None
    J = model.jacobian(est.x, table)
    J0 = model.jacobian(est.x, done)
    P = J.shape[-1]
    ident = analyse(np.concatenate([J.reshape(-1, P), J0.reshape(-1, P)]), model.parameter_names(),
                    priority=model.priority())
    free = ident.free
    sigma = max(est.sigma, 1e-6)
    A = J[:, :, free].reshape(int(table["pose"].max()) + 1, -1, int(free.sum())) / sigma
    B = J0[:, :, free].reshape(-1, int(free.sum())) / sigma
    sel = ioptimal.select(A, m, B.T @ B, ioptimal.eval_matrix(J[:, :, free]))
    return {**pose_campaign(table, sel.index), "selection_s": sel.elapsed_s,
            "criterion": "I-optimal on the calibrated estimate: mean predicted squared 3-D error over the "
                         "candidates' crossings, earlier stages' information as prior",
            "earlier_measurements": int(len(done["pixel"])), "estimate_sigma_m": float(est.sigma),
            "free_parameters": [n for n, f in zip(model.parameter_names(), free) if f],
            "predicted_rms_3d_error_m": float(np.sqrt(sel.value)),
            "prediction_note": "independent crossing errors at the residual scatter: optimistic, the 5 crossings of "
                               "a pose share the arm's repeatability error (bench_plan_scanner: measured ≈ 1.3× this)"}
