"""D-optimal robot poses for a camera calibration: the images a robot should take of a board so
that the camera's intrinsics, its hand-eye transform, the board's pose and (optionally) the
robot's joint offsets are best determined — written as an executable pose campaign.

Before any calibration the cell is known nominally (`Setup`): the URDF chain, a home
configuration where the camera sees the board's centre at `distance_m`, the hand-eye transform
(tool frame: flange → camera eye-in-hand, flange → board eye-to-hand) and nominal intrinsics.

Candidates (`candidate_views`): camera poses in the board frame looking at the board from a tilt
θ (0 … `max_tilt_rad` between the optical axis and the board's normal) around any azimuth, a
distance within ±30 % of `distance_m`, a roll about the optical axis, and the board's centre at a
random place of the image (`centre_px`); each is solved for joints by the vectorised damped
Newton IK (`pipeline.compensate.ik.multistart`: from home, then random seeds; within the
URDF's joint limits) and kept only when the nominal camera sees every corner inside the image by
`margin_px`.

Selection: every candidate image's stacked corner Jacobian (2 rows per corner, px) over the
free parameters (`analyse`'s rank test over all candidates, the kept groups) is reduced to its
triangular factor (same information, L × L), and `pipeline.plan.doptimal.select` (greedy +
Fedorov exchange) picks m images maximising log det of the information.  Corners are weighed
as independent (the detector's noise); the robot's pose error shared by an image's corners is
not part of the criterion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.camera import projection as pj
from pipeline.camera.start import homogeneous, inverse
from pipeline.camera.targets import Target
from pipeline.identify.identifiability import analyse
from pipeline.identify.model import Table
from pipeline.plan.doptimal import Selection, select

GROUPS = ("registration",)  # fitted by default: intrinsics (k1, k2, p1, p2), hand-eye, board pose


@dataclass(frozen=True)
class Setup:
    """The nominal cell: the board, nominal intrinsics k (`projection` order, px), a home
    configuration q_home (rad) where the camera sees the board's centre straight on at
    `distance_m` (m), and the hand-eye transform (x, y, z m, roll, pitch, yaw rad; None: the
    camera on the flange's z axis, or the board facing back along it)."""

    target: Target
    k: np.ndarray
    q_home: np.ndarray
    distance_m: float = 0.5
    hand_eye: np.ndarray | None = None


def nominal(model, setup: Setup) -> np.ndarray:
    """The planning parameter vector: the nominal robot, `setup`'s hand-eye and intrinsics, the board placed."""
    x = model.nominal().copy()
    it = model.parameter_names().index("tool.x")
    he = setup.hand_eye
    if he is None:
        he = np.zeros(6) if model.mount == "tip" else np.array([0.0, 0.0, 0.0, np.pi, 0.0, 0.0])
    x[it:it + 6] = he
    x[model.n_kin:] = setup.k
    from pipeline.simulate.camera_images import place_board

    return place_board(model, x, setup.q_home, setup.target, setup.distance_m)


def look_at(tilt: np.ndarray, azimuth: np.ndarray, distance: np.ndarray, roll: np.ndarray, centre_n: np.ndarray,
            centre: np.ndarray) -> np.ndarray:
    """Camera poses in the board frame T_board_cam (n,4,4): the camera `distance` (m) from the
    board point `centre`, its optical axis `tilt` (rad) off the board's normal toward `azimuth`,
    turned `roll` about that axis, then rotated so that `centre` is seen along the normalised
    image direction `centre_n` (n,2) (x', y')."""
    n = len(tilt)
    v = np.stack([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), -np.cos(tilt)], 1)
    C = centre + distance[:, None] * v  # camera centre (the board's -z side: its axes along the camera's)
    z = -v
    ref = np.where(np.abs(z[:, :1]) < 0.9, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    x0 = np.cross(ref, z)
    x0 /= np.linalg.norm(x0, axis=1, keepdims=True)
    y0 = np.cross(z, x0)
    c, s = np.cos(roll)[:, None], np.sin(roll)[:, None]
    xr, yr = c * x0 + s * y0, -s * x0 + c * y0
    R0 = np.stack([xr, yr, z], 2)  # columns: camera axes in the board frame
    w = np.c_[centre_n, np.ones(n)]
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    R1 = _rotation_onto(np.array([0.0, 0, 1]), w)  # e_z → w
    return homogeneous(R0 @ np.swapaxes(R1, 1, 2), C)


def _rotation_onto(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotations (n,3,3) taking the unit vector a onto each unit row of b (Rodrigues)."""
    k = np.cross(a, b)
    s = np.linalg.norm(k, axis=1)
    c = b @ a
    K = np.zeros((len(b), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K = K - np.swapaxes(K, 1, 2)
    f = np.where(s > 1e-12, (1 - c) / np.maximum(s, 1e-12) ** 2, 0.5)
    return np.eye(3) + K + f[:, None, None] * (K @ K)


@dataclass
class Candidates:
    """Reachable candidate images: joints (N, n_joints) rad, and per image its view: tilt (rad),
    azimuth (rad), distance (m), roll (rad), the board centre's predicted pixel (N,2) px and the
    smallest distance of a corner to the image border (px)."""

    q: np.ndarray
    tilt: np.ndarray
    azimuth: np.ndarray
    distance: np.ndarray
    roll: np.ndarray
    centre_px: np.ndarray
    border_px: np.ndarray
    drawn: int  # views drawn to find them


def candidate_views(model, x: np.ndarray, setup: Setup, n: int, rng: np.random.Generator,
                    max_tilt_rad: float = np.radians(40), margin_px: float = 30.0, seeds: int = 6) -> Candidates:
    """n candidate images (module docstring), drawn in batches until n are reachable and seen."""
    from pipeline.compensate.ik import ChainKinematics, multistart
    from pipeline.simulate.camera_images import visible

    kin = ChainKinematics.of(model.kin)
    xk, k = model.split(x)
    lo = np.where(np.isfinite(kin.lower), kin.lower, -np.pi)
    hi = np.where(np.isfinite(kin.upper), kin.upper, np.pi)
    starts = np.r_[setup.q_home[None], rng.uniform(lo, hi, (seeds, kin.n_joints))]
    w, h = model.image_size
    centre = setup.target.points.mean(0)
    parts: list[tuple] = []
    found, drawn = 0, 0
    for _ in range(200):
        b = max(64, 2 * (n - found))
        tilt = max_tilt_rad * np.sqrt(rng.uniform(0, 1, b))  # uniform over the cap of directions
        az, roll = rng.uniform(-np.pi, np.pi, b), rng.uniform(-np.pi / 2, np.pi / 2, b)
        dist = setup.distance_m * rng.uniform(0.7, 1.3, b)
        uv = np.c_[rng.uniform(0.3 * w, 0.7 * w, b), rng.uniform(0.3 * h, 0.7 * h, b)]
        cn = (uv - k[2:4]) / k[:2]
        T = look_at(tilt, az, dist, roll, cn, centre)  # T_board_cam
        T_chain = T if model.mount == "tip" else inverse(T)
        q, ok = multistart(kin, xk, T_chain[:, :3, 3], T_chain[:, :3, :3], starts)
        drawn += b
        for i in np.flatnonzero(ok):
            T_cb = inverse(T[i])
            if visible(k, model.lens, T_cb, setup.target, model.image_size, margin_px):
                P = setup.target.points @ T_cb[:3, :3].T + T_cb[:3, 3]
                px = pj.project(k, P, model.lens)
                border = float(np.min(np.r_[px.ravel(), (np.array([w - 1, h - 1]) - px).ravel()]))
                c = pj.project(k, (centre @ T_cb[:3, :3].T + T_cb[:3, 3])[None], model.lens)[0]
                parts.append((q[i], tilt[i], az[i], dist[i], roll[i], c, border))
                found += 1
                if found == n:
                    break
        if found == n:
            break
    if found < n:
        raise RuntimeError(f"only {found} of {n} candidate views are reachable and see the whole board "
                           f"after {drawn} drawn: move the board or the home configuration")
    cols = list(zip(*parts))
    return Candidates(np.array(cols[0]), *(np.array(c) for c in cols[1:]), drawn=drawn)


def image_table(model, x: np.ndarray, q: np.ndarray, target: Target) -> Table:
    """The camera measurement table of images at configurations q (N, n_joints): every corner of
    the board, detected exactly where the model at x projects it (one image per row of q)."""
    nc = target.n_corners
    N = len(q)
    t = {"joint_positions": np.repeat(q, nc, 0), "image": np.repeat(np.arange(N), nc),
         "corner": np.tile(np.arange(nc), N), "point": np.tile(target.points, (N, 1))}
    t["pixel"] = model.predict(x, t)[0]
    t["record"] = np.arange(N * nc)
    return t


def information_blocks(model, x: np.ndarray, table: Table, fixed: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Per image the triangular factor (N, L, L) of its corners' Jacobian over the L free
    parameters (px per unit), and the free mask (rank test over all images, `fixed` held)."""
    J = model.jacobian(x, table)  # (rows, 2, P)
    names = model.parameter_names()
    priority = getattr(model, "priority", lambda: None)()
    ident = analyse(J.reshape(-1, J.shape[-1]), names, np.array([nm in fixed for nm in names]), priority)
    N = len(np.unique(table["image"]))
    A = J[:, :, ident.free].reshape(N, -1, int(ident.free.sum()))
    return np.linalg.qr(A, mode="r"), ident.free


def plan_images(model, x: np.ndarray, cand: Candidates, target: Target, m: int,
                fixed: tuple[str, ...]) -> tuple[Selection, np.ndarray]:
    """D-optimal choice of m of the candidate images (module docstring): (selection, free mask)."""
    A, free = information_blocks(model, x, image_table(model, x, cand.q, target), fixed)
    return select(A, m), free


def campaign_part(desc, cand: Candidates, idx: np.ndarray, setup: Setup, model, x: np.ndarray,
                  urdf_path: str) -> dict:
    """The campaign file's camera part (schemas/campaign.schema.json, measurement: pose): per chosen
    image its joints (rad) and the view the planning model predicts there; the nominal cell."""
    names = model.parameter_names()
    ib, it = names.index("base.x"), names.index("tool.x")
    rows = [{"index": i, "candidate": int(j), "joints_rad": cand.q[j].tolist(), "tilt_rad": float(cand.tilt[j]),
             "azimuth_rad": float(cand.azimuth[j]), "distance_m": float(cand.distance[j]),
             "roll_rad": float(cand.roll[j]), "board_centre_px": cand.centre_px[j].tolist(),
             "border_px": float(cand.border_px[j])} for i, j in enumerate(idx)]
    return {"measurement": "pose", "instrument": "camera", "joint_names": list(desc.joint_names),
            "urdf": {"path": urdf_path, "root": desc.root, "tip": desc.tip, "robot": desc.name},
            "camera": {"target": setup.target.spec, "mount": model.mount, "lens": model.lens,
                       "image_size": list(model.image_size),
                       "intrinsics": dict(zip(model.extra_names(), map(float, setup.k))),
                       "home_joints_rad": np.asarray(setup.q_home, float).tolist(), "distance_m": setup.distance_m,
                       "hand_eye": x[it:it + 6].tolist(), "board_frame": x[ib:ib + 6].tolist()},
            "measurements": rows}
