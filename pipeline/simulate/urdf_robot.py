"""Campaigns of any URDF robot with any generic measurement type, for tests and planning.

A random truth (errors of stated size on every joint origin and offset, a registration, a tool
offset) and configurations within the joint limits; for plane contacts and point coincidence the
configurations are moved (damped least squares on the true chain's joint Jacobian) until the true
tool point lies on its plane / on its group's point, as a robot touching a face or sitting in a
socket would.  Everything here is the *truth*; the recording gets only readings and measurements.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.measurements.composed import Composed
from pipeline.models import chain as ch
from pipeline.plan.urdf_robot import configurations
from pipeline.recording.joint_state_batch import COMMANDED_POSITIONS


@dataclass(frozen=True)
class Truth:
    x: np.ndarray  # the model's full parameter vector
    planes: list[dict]  # plane campaigns: name, normal, offset
    points: np.ndarray  # coincidence: (groups, 3) m in the base frame


def random_truth(model: Composed, rng: np.random.Generator, error_m: float, error_rad: float,
                 registration: bool = True) -> np.ndarray:
    """The nominal vector plus N(0, error) on joint origins and offsets; with `registration`, a
    random instrument placement (±1 m, any yaw, ±10° tilt) and a tool offset of ~0.1 m."""
    x = model.nominal().copy()
    names = model.parameter_names()
    for i, n in enumerate(names):
        head, k = n.rsplit(".", 1) if "." in n else ("", n)
        if head in ("base", "tool") or head.startswith(("target", "plane", "point")):
            continue
        x[i] += rng.normal(0, error_m if k in ("x", "y", "z") else error_rad)
    if registration:
        b = names.index("base.x")
        x[b:b + 3] = rng.uniform(-1, 1, 3)
        x[b + 3:b + 6] = (*rng.uniform(-0.17, 0.17, 2), rng.uniform(-np.pi, np.pi))
        t = names.index("tool.x")
        x[t:t + 3] = rng.normal(0, 0.05, 3)
        x[t + 3:t + 6] = rng.normal(0, 0.3, 3)
    return x


def _settle(model: Composed, x: np.ndarray, q: np.ndarray, target, rows_normal=None, iters: int = 60):
    """Damped least squares on the joints until the true tool point meets `target` (n,3) — or,
    with `rows_normal` (n,3), until n·p equals `target` (n,) — within the limits."""
    kin = model.kin
    xk = model.split(x)[0]
    lo = np.where(np.isfinite(kin.lower), kin.lower, -np.inf)
    hi = np.where(np.isfinite(kin.upper), kin.upper, np.inf)
    q = q.copy()
    for _ in range(iters):
        p, Jq = ch.joint_jacobian(kin.chain(), xk, q)
        if rows_normal is None:
            e = target - p  # (n,3)
            A = Jq
        else:
            e = (target - np.einsum("ni,ni->n", rows_normal, p))[:, None]
            A = np.einsum("ni,nij->nj", rows_normal, Jq)[:, None, :]
        if np.max(np.abs(e)) < 1e-13:
            break
        lam = 1e-6
        JJt = A @ np.swapaxes(A, 1, 2) + lam * np.eye(A.shape[1])
        dq = np.einsum("nji,nj->ni", A, np.linalg.solve(JJt, e[..., None])[..., 0])
        q = np.clip(q + dq, lo, hi)
    return q


def campaign(model: Composed, truth_x: np.ndarray, n: int, seed: int, measure: str, noise_m: float = 0.0,
             noise_rad: float = 0.0, n_groups: int = 2, planes: list[dict] | None = None,
             q: np.ndarray | None = None, true_joints=None):
    """(table for `write_urdf_recording`, Truth): n measurements of `measure` on the true robot, at
    random configurations or, given `q` (n, n_joints), at a campaign's (for plane and coincidence
    measurements the robot starts there and moves onto its plane / socket).  `true_joints` (point and
    pose): readings (n, J) → where the joints truly stand (a compliant joint's deflection).  The table's
    ``commanded_positions`` are the configurations the controller was sent (before a plane / socket
    move and joint reading noise)."""
    rng = np.random.default_rng(seed)
    given = q is not None
    if given:
        q = np.asarray(q, float)
        n = q.shape[0]
    else:
        q = configurations(model.kin, n, seed)
    truth_planes, truth_points = planes or [], np.zeros((0, 3))
    if measure == "plane":
        p, *_ = model.tool(truth_x, q)
        if not truth_planes:  # three axis planes and two oblique ones through the middle of the reached points
            mid = np.median(p, axis=0)
            normals = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1), "xy": (0.6, 0.8, 0), "yz": (0, 0.6, 0.8)}
            truth_planes = [{"name": a, "normal": list(map(float, nv)), "offset": float(np.dot(nv, mid))}
                            for a, nv in normals.items()]
        k = np.arange(n) % len(truth_planes)
        N = np.array([truth_planes[i]["normal"] for i in k], float)
        N /= np.linalg.norm(N, axis=1, keepdims=True)
        d = np.array([truth_planes[i]["offset"] for i in k], float)
        q_cmd = q.copy()
        q = _settle(model, truth_x, q, d, rows_normal=N)
        p, *_ = model.tool(truth_x, q)
        ok = np.abs(np.einsum("ni,ni->n", N, p) - d) < 1e-10
        table = {"joint_positions": q[ok], "plane": np.array([truth_planes[i]["name"] for i in k[ok]], object),
                 COMMANDED_POSITIONS: q_cmd[ok]}
    elif measure == "coincidence":
        g = np.arange(n) % n_groups
        seeds = configurations(model.kin, n_groups, seed + 7)
        P, *_ = model.tool(truth_x, seeds)
        if not given:
            q = np.clip(seeds[g] + rng.normal(0, 0.35, q.shape), model.kin.lower, model.kin.upper)
        q_cmd = q.copy()
        q = _settle(model, truth_x, q, P[g])
        p, *_ = model.tool(truth_x, q)
        ok = np.linalg.norm(p - P[g], axis=1) < 1e-10
        table = {"joint_positions": q[ok], "group": np.array([f"socket{i}" for i in g[ok]], object),
                 COMMANDED_POSITIONS: q_cmd[ok]}
        truth_points = P
    else:
        p, _, R, _ = model.tool(truth_x, q if true_joints is None else true_joints(q))
        table = {"joint_positions": q, "position": p + rng.normal(0, noise_m, p.shape) if noise_m else p,
                 COMMANDED_POSITIONS: q.copy()}
        if measure == "pose":
            rot = Rotation.from_matrix(R)
            if noise_rad:
                rot = Rotation.from_rotvec(rng.normal(0, noise_rad, (n, 3))) * rot
            table["orientation"] = rot.as_quat()
        else:
            table["target"] = np.zeros(n, int)
    if measure in ("plane", "coincidence") and noise_m:
        table["joint_positions"] = table["joint_positions"] + rng.normal(0, noise_rad, table["joint_positions"].shape)
    return table, Truth(truth_x, truth_planes, truth_points)
