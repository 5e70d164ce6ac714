"""The operator of seed 001's campaign, as the simulator runs it (pure numpy, SI).

For each pose the operator, who sees the true image (so the *true* model decides):
  1. brings the scanner over the pattern: camera centre at a stand-off `depth` (m) from an aim point
     on the pattern, optical axis tilted by `tilt` (rad) towards the base, wrist roll `roll` (rad);
  2. jogs the arm (minimum-norm joint correction) until the laser stripe lies on the nearest grid
     line — a row, a column or a diagonal of the pattern;
  3. latches the encoders and picks `corners` crossings closest to the image centre.
`draw_pose` is the paper's operator (random stand-off from an image row, aim, tilt, roll);
`backed_off_pose` the same from given aim, tilt and roll, backing off until enough crossings are
in the image (how a first-stage planned pose is executed: `plan/scorbot_scanner.first_stage`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.models import camera as cam
from pipeline.models import serial_arm
from pipeline.simulate.scanner_geometry import camera_pose, floor_line, newton, project

MIN_DEPTH_M, MAX_DEPTH_M = 0.12, 0.70  # stand-offs the operator uses (camera centre to aim point)
BACK_OFF_M = 0.025
ROLL_TRIES_RAD = (0.0, 0.25, -0.25, 0.5, -0.5)


@dataclass(frozen=True)
class OperatorPose:
    """A first-stage pose as the operator takes it (no calibrated model yet): aim point (3,) m on the
    pattern, starting stand-off m, tilt rad, wrist roll rad (`backed_off_pose`)."""

    aim: tuple[float, float, float]
    standoff: float
    tilt: float
    roll: float


def draw_pose(arm, xa: np.ndarray, s: np.ndarray, pattern, campaign, rng: np.random.Generator,
              image_size: tuple[int, int]):
    """One pose whose true stripe lies on a grid line with ≥ `corners` visible crossings, or None
    (the paper's operator: random stand-off, aim, tilt and roll)."""
    _, H = image_size
    z0 = pattern.origin[2]
    a_v = s[cam.I_SV] / s[cam.I_F]
    # stand-off: stripe at a random image row in the middle 60 %, depth 0.12-0.70 m
    vf = a_v * ((rng.uniform(0.1, 0.9) if campaign.spread else rng.uniform(0.2, 0.8)) * H - s[cam.I_V0])
    den = np.tan(s[cam.I_TH]) + vf
    if den <= 0:
        return None
    depth = s[cam.I_B] / den
    if not MIN_DEPTH_M <= depth <= MAX_DEPTH_M:
        return None
    lo_xy, hi_xy = aim_box(pattern)
    aim = np.append(rng.uniform(lo_xy, hi_xy), z0)
    tilt = rng.uniform(-campaign.max_tilt_rad, campaign.max_tilt_rad)
    roll = rng.uniform(-np.pi / 2, np.pi / 2)
    return pose_on_line(arm, xa, s, pattern, campaign, image_size, aim, depth, tilt, roll)


def aim_box(pattern) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) x, y of the aim points the operator uses (m, base frame): 60 mm inside the grid."""
    P = pattern.corners()
    return P[:, :2].min(axis=0) + 0.06, P[:, :2].max(axis=0) - 0.06


def backed_off_pose(arm, xa: np.ndarray, s: np.ndarray, pattern, campaign, image_size: tuple[int, int],
                    aim: np.ndarray, depth: float, tilt: float, roll: float):
    """`pose_on_line` from the given stand-off, backing off by 25 mm while fewer than `corners`
    crossings are in the image (the operator watches the image), up to 0.70 m; if no stand-off
    works, the same with the wrist rolled by ±0.25, ±0.5 rad (`ROLL_TRIES_RAD`); None if none does."""
    for dr in ROLL_TRIES_RAD:
        r = float(np.clip(roll + dr, -np.pi / 2, np.pi / 2))
        for d in np.arange(max(depth, MIN_DEPTH_M), MAX_DEPTH_M + 1e-9, BACK_OFF_M):
            plan = pose_on_line(arm, xa, s, pattern, campaign, image_size, np.asarray(aim, float), float(d), tilt, r)
            if plan is not None:
                return plan
    return None


def camera_at(xa: np.ndarray, s: np.ndarray, aim: np.ndarray, depth: float, tilt: float, roll: float):
    """Joints (5,) rad putting the camera centre `depth` (m) from `aim` (base frame) along an optical
    axis tilted by `tilt` (rad) from the vertical towards the base's radial direction, wrist roll
    `roll` (rad); None when the arm cannot (arm parameters `xa`, hand-eye of scanner `s`)."""
    q1 = np.arctan2(aim[1], aim[0])
    e_rad = np.array([np.cos(q1), np.sin(q1), 0.0])
    axis = -np.cos(tilt) * np.array([0, 0, 1.0]) + np.sin(tilt) * e_rad  # optical axis, roughly the flange z
    C_target = aim - depth * axis

    def stage1(Q4: np.ndarray) -> np.ndarray:
        Q = np.concatenate([Q4, np.full((len(Q4), 1), roll)], axis=1)
        _, C = camera_pose(xa, s, Q)
        R_f, _ = serial_arm.forward(xa, Q)
        return np.concatenate([C - C_target, (R_f[:, :, 2] @ e_rad - np.sin(tilt))[:, None]], axis=1)

    q4 = newton(stage1, np.array([q1, -0.4, 0.8, -0.4]))
    if np.linalg.norm(stage1(q4[None])) > 1e-9:
        return None
    return np.append(q4, roll)


def pose_on_line(arm, xa: np.ndarray, s: np.ndarray, pattern, campaign, image_size: tuple[int, int],
                 aim: np.ndarray, depth: float, tilt: float, roll: float):
    """(q rad, corner indices) of the arm (parameters `xa`, scanner `s`) brought to the camera pose
    of (aim, depth, tilt, roll) and jogged until its stripe lies on the nearest grid line; None when
    the joints leave their limits or fewer than `corners` crossings are in the image."""
    W, H = image_size
    P = pattern.corners()
    z0 = pattern.origin[2]
    sq = pattern.square_m
    q = camera_at(xa, s, aim, depth, tilt, roll)
    if q is None:
        return None
    q1 = np.arctan2(aim[1], aim[0])
    e_rad = np.array([np.cos(q1), np.sin(q1), 0.0])
    axis = -np.cos(tilt) * np.array([0, 0, 1.0]) + np.sin(tilt) * e_rad
    # nearest grid line (rows, columns, diagonals) to the current stripe
    R_c, C = camera_pose(xa, s, q[None])
    p0, dvec = floor_line(R_c, C, s, z0)
    if not np.all(np.isfinite(dvec)):
        return None
    ang = np.arctan2(dvec[0, 1], dvec[0, 0]) % np.pi
    fams = np.array([0, np.pi / 4, np.pi / 2, 3 * np.pi / 4])
    fam = int(np.argmin(np.abs(((ang - fams) + np.pi / 2) % np.pi - np.pi / 2)))
    u = np.array([np.cos(fams[fam]), np.sin(fams[fam]), 0.0])
    nrm = np.array([-u[1], u[0], 0.0])
    spacing = sq * (np.sqrt(0.5) if fam in (1, 3) else 1.0)
    o = np.asarray(pattern.origin)
    # the stripe point seen at the image centre column
    t_mid = np.dot(C[0] + depth * axis - p0[0], dvec[0])
    mid = p0[0] + t_mid * dvec[0]
    c = nrm @ o + np.round((nrm @ (mid - o)) / spacing) * spacing
    foot = mid + (c - nrm @ mid) * nrm
    A, B = foot - 0.05 * u, foot + 0.05 * u

    n_c, d_c = cam.laser_plane(s)

    def stage2(Q: np.ndarray) -> np.ndarray:
        Rc, Cc = camera_pose(xa, s, Q)
        n = Rc @ n_c
        return np.stack([np.sum(n * (A - Cc), axis=1) - d_c, np.sum(n * (B - Cc), axis=1) - d_c], axis=1)

    q = newton(stage2, q)
    if np.max(np.abs(stage2(q[None]))) > 1e-10 or np.any(q < arm.lower) or np.any(q > arm.upper):
        return None
    on_line = np.abs((P - foot) @ nrm) < 1e-9
    idx = np.flatnonzero(on_line)
    if idx.size < campaign.corners:
        return None
    R_c, C = camera_pose(xa, s, np.repeat(q[None], idx.size, axis=0))
    px, z = project(R_c, C, s, P[idx])
    inside = (z > 0) & (px[:, 0] > 10) & (px[:, 0] < W - 11) & (px[:, 1] > 10) & (px[:, 1] < H - 11)
    idx, px = idx[inside], px[inside]
    if idx.size < campaign.corners:
        return None
    # M crossings closest to the image centre column
    keep = np.argsort(np.abs(px[:, 0] - W / 2))[:campaign.corners]
    if campaign.spread:  # evenly along the visible stripe, out to the image edges
        order = np.argsort(px[:, 0])
        keep = order[np.unique(np.linspace(0, order.size - 1, campaign.corners).round().astype(int))]
    return q, idx[np.sort(keep)]

