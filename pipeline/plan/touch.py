"""Executable touch campaigns (seed 000): candidate pools the robot can run, and their planning.

A candidate is what a controller executes: move (joint space) to an approach configuration,
then search at constant joint rate ``dq`` (rad per m of travel, the planning model's
straight line along −normal) until the wire touches, or the travel runs out.  The approach
configuration comes from the *planning* model's inverse kinematics (the nominal model for a
first campaign, a calibrated one for a second stage), so the robot runs the campaign in joint
space whatever its controller's model.

Robustness to the robot being off: targets are drawn only where the predicted contact point
lies at least `margin_m` inside every edge of its face (on faces narrower than twice the
margin, only their middle `1 − 2·NARROW_KEEP` band is excluded: the margin shrinks to
`NARROW_KEEP` of the face width there, stated in the campaign).  Pure numpy except the IK.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pipeline.models import ik, serial_arm
from pipeline.models.jig import Face, Jig
from pipeline.models.serial_arm import SerialArm
from pipeline.simulate.arc_welder import IK_SEEDS, Campaign, _targets

NARROW_KEEP = 0.35  # on a face narrower than 2·margin, keep targets this fraction of its width from each edge
MAX_SEARCH_RATE = 50.0  # rad per m of search: a faster joint is a search through a singularity (not a candidate)


@dataclass
class TouchPool:
    """Candidate touch measurements (arrays over N candidates), all in the jig frame {W}, SI."""

    face: np.ndarray  # (N,) index into jig.faces
    axis: np.ndarray  # (N,) 0/1/2
    sign: np.ndarray  # (N,) ±1, outward normal sign
    q_approach: np.ndarray  # (N, n_joints) rad
    dq: np.ndarray  # (N, n_joints) rad per m of search travel
    travel: np.ndarray  # (N,) m, predicted search travel to contact (planning model)
    target: np.ndarray  # (N, 3) m, predicted contact point (planning model)
    edge_distance: np.ndarray  # (N,) m, predicted contact's distance to the nearest face edge

    @property
    def q_contact(self) -> np.ndarray:
        """Predicted contact configurations (N, n_joints), rad."""
        return self.q_approach + self.travel[:, None] * self.dq

    def take(self, idx: np.ndarray) -> "TouchPool":
        return TouchPool(**{k: getattr(self, k)[idx] for k in self.__dataclass_fields__})

    def table(self) -> dict[str, np.ndarray]:
        """A `TouchModel` table at the predicted contacts (coordinates from the drawing)."""
        n = self.face.size
        return {"joint_positions": self.q_contact, "axis": self.axis,
                "coordinate": self.target[np.arange(n), self.axis], "record": np.arange(n)}


def face_margin(f: Face, margin_m: float) -> tuple[float, float]:
    """Margin actually kept on each of the face's two tangential extents (m)."""
    return tuple(min(margin_m, NARROW_KEEP * (hi - lo)) for lo, hi in f.extent)


def shrunk(jig: Jig, margin_m: float) -> Jig:
    """The jig with every face's extent shrunk by its margin (`face_margin`)."""
    faces = []
    for f in jig.faces:
        ma, mb = face_margin(f, margin_m)
        (a0, a1), (b0, b1) = f.extent
        faces.append(replace(f, extent=((a0 + ma, a1 - ma), (b0 + mb, b1 - mb))))
    return replace(jig, faces=tuple(faces))


def edge_distance(jig: Jig, face: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Signed distance (m) of points p (N,3) inside their face's extent (negative: off the face)."""
    lo = np.array([[f.extent[0][0], f.extent[1][0]] for f in jig.faces])[face]
    hi = np.array([[f.extent[0][1], f.extent[1][1]] for f in jig.faces])[face]
    other = np.array([f.other_axes() for f in jig.faces])[face]
    t = np.take_along_axis(p, other, axis=1)
    return np.min(np.minimum(t - lo, hi - t), axis=1)


def search(x: np.ndarray, q_a: np.ndarray, dq: np.ndarray, axis: np.ndarray, sign: np.ndarray,
           coordinate: np.ndarray, tip_offset: np.ndarray | None = None, travel_m: float = 0.09,
           step_m: float = 1e-3, iters: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Travel s (m) at which the tip of model x (plus `tip_offset`, m) first reaches each face
    plane along the joint-space search, and the gap at the start (m, > 0: the search starts
    outside the material).  The first crossing is bracketed on a `step_m` grid up to
    `travel_m` (the path is a straight line in joint space, not in space), then refined by
    Newton with the analytic joint Jacobian, kept inside the bracket.  No crossing: s = inf."""
    n = axis.size
    r = np.arange(n)
    off = np.zeros((n, 3)) if tip_offset is None else tip_offset
    grid = np.arange(0.0, travel_m + step_m, step_m)
    qg = q_a[:, None, :] + grid[None, :, None] * dq[:, None, :]
    pg = serial_arm.tip_position(x, qg.reshape(-1, q_a.shape[1])).reshape(n, grid.size, 3) + off[:, None, :]
    g = sign[:, None] * (pg[r, :, axis] - coordinate[:, None])  # (n, grid)
    g0 = g[:, 0]
    cross = (g[:, :-1] > 0) & (g[:, 1:] <= 0)
    found = cross.any(axis=1)
    k = np.argmax(cross, axis=1)
    lo, hi = grid[k], grid[k + 1]
    s = np.where(found, lo + step_m * g[r, k] / np.where(found, g[r, k] - g[r, k + 1], 1.0), 0.0)
    for _ in range(iters):
        p, Jq = serial_arm.joint_jacobian(x, q_a + s[:, None] * dq)
        gs = sign * ((p + off)[r, axis] - coordinate)
        slope = sign * np.einsum("nj,nj->n", Jq[r, axis], dq)
        s = np.clip(s - gs / np.where(np.abs(slope) > 1e-12, slope, -1e-12), lo, hi)
    return np.where(found & (g0 > 0), s, np.inf), g0


def pool(arm: SerialArm, jig: Jig, n: int, seed: int = 0, margin_m: float = 0.010,
         campaign: Campaign = Campaign()) -> TouchPool:
    """About n executable candidates planned on `arm` (the planning model), their predicted
    contacts at least the face margin inside every edge.  Deterministic for a seed."""
    rng = np.random.default_rng(seed)
    inner = shrunk(jig, margin_m)
    parts: list[TouchPool] = []
    for _ in range(6):  # IK failures and contacts predicted off the shrunk face: draw more until n
        have = sum(p.face.size for p in parts)
        if have >= n:
            break
        parts.append(_batch(arm, jig, inner, int((n - have) * 1.6) + 8, rng, campaign))
    cat = TouchPool(**{k: np.concatenate([getattr(p, k) for p in parts]) for k in TouchPool.__dataclass_fields__})
    return cat.take(np.arange(min(n, cat.face.size)))


def _batch(arm: SerialArm, jig: Jig, inner: Jig, n_try: int, rng: np.random.Generator, campaign: Campaign) -> TouchPool:
    x = arm.vector()
    faces, P, R = _targets(inner, n_try, rng, campaign.approach_offset_m, campaign.max_tilt_rad)
    q_a, ok = ik.solve(x, P, R, IK_SEEDS, arm.lower, arm.upper, iters=40)
    faces, q_a = faces[ok], q_a[ok]
    normals = np.stack([jig.faces[f].normal for f in faces])
    Jp = ik.pose_jacobian(x, q_a)
    twist = np.concatenate([-normals, np.zeros_like(normals)], axis=1)
    dq = np.linalg.solve(Jp, twist[..., None])[..., 0]
    axis = np.array([jig.faces[f].axis_index for f in faces], int)
    sign = np.array([jig.faces[f].normal_sign for f in faces], float)
    coord = np.array([jig.faces[f].coordinate for f in faces])
    s, g0 = search(x, q_a, dq, axis, sign, coord, travel_m=campaign.search_travel_m)
    good = np.isfinite(s)
    s = np.where(good, s, 0.0)
    p = serial_arm.tip_position(x, q_a + s[:, None] * dq)
    good &= (edge_distance(inner, faces, p) >= -1e-9) & (g0 > 0) & (s > 0) & (np.abs(dq).max(axis=1) <= MAX_SEARCH_RATE)
    idx = np.flatnonzero(good)
    return TouchPool(face=faces[idx], axis=axis[idx], sign=sign[idx], q_approach=q_a[idx], dq=dq[idx],
                     travel=s[idx], target=p[idx], edge_distance=edge_distance(jig, faces[idx], p[idx]))
