"""Vectorised inverse kinematics of a serial chain: damped Newton / Levenberg–Marquardt with the
analytic joint Jacobian, and the nominal controller's multi-start rule.

Kinematics plug in through `Kinematics` (forward pose and joint Jacobian with its angular part
at a parameter vector); `ChainKinematics` wraps any robot described by a `Chain`: seed 000's
D-H + Hayati arm and URDF robots alike.  All poses in the work frame {W}, m and rad; orientation
errors are weighed like a `LEVER_M` lever.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from pipeline.models import chain as ch

LEVER_M = 0.3  # orientation weighed like a 0.3 m lever (rad → m) in the Newton steps and σ_min


class Kinematics(Protocol):
    """What the solver needs of a robot: pose and joint Jacobian at (x, q)."""

    n_joints: int
    lower: np.ndarray
    upper: np.ndarray

    def pose(self, x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tool rotations (N,3,3) and positions (N,3) m in {W}."""
        ...

    def pose_jacobian(self, x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(R (N,3,3), p (N,3), J (N,6,n): d[p; ω]/dq, ω the world-frame rotation vector)."""
        ...


@dataclass(frozen=True, eq=False)
class ChainKinematics:
    """`Kinematics` of any robot described by a `pipeline.models.chain.Chain` — seed 000's
    `SerialArm`, a `UrdfArm` — whose parameters come first in the parameter vector (the
    measurement model's extra parameters, if any, follow and are ignored here)."""

    chain: ch.Chain
    n_joints: int
    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def of(cls, kin) -> "ChainKinematics":
        """From a kinematics description with `chain()`, `n_joints`, `lower`, `upper`."""
        return cls(kin.chain(), int(kin.n_joints), np.asarray(kin.lower, float), np.asarray(kin.upper, float))

    def _x(self, x):
        return np.asarray(x, float)[: self.chain.n_params]

    def pose(self, x, q):
        return ch.forward(self.chain, self._x(x), np.atleast_2d(np.asarray(q, float)))

    def pose_jacobian(self, x, q):
        q = np.atleast_2d(np.asarray(q, float))
        R, p, *_ = ch.walk(self.chain, self._x(x), q, True)  # one walk: joint_jacobian below reuses it (memoised)
        _, Jp, Jw = ch.joint_jacobian(self.chain, self._x(x), q, angular=True)
        return R.copy(), p.copy(), np.concatenate([Jp, Jw], axis=1)

    def point_jacobian(self, x, q) -> np.ndarray:
        """d tool point / d parameters (N, 3, P) over the chain's parameters."""
        return ch.jacobian(self.chain, self._x(x), np.atleast_2d(np.asarray(q, float)))[1]


SerialArmKinematics = ChainKinematics  # seed 000's arm: ChainKinematics.of(SerialArm)


@dataclass(frozen=True)
class IKOptions:
    iters: int = 40
    tol_m: float = 1e-11  # converged when the lever-weighted pose error is below this (m)
    damping: float = 1e-10  # Levenberg–Marquardt λ (m²), raised ×10 on a rejected step
    max_step_rad: float = 0.3
    give_up_damping: float = 1e-2  # a row stops (not converged) once λ has grown this far
    singular_threshold_m: float = 5e-3  # σ_min of the lever-scaled Jacobian (m per rad), nominal or calibrated


def pose_error(R: np.ndarray, p: np.ndarray, R_t: np.ndarray | None, p_t: np.ndarray) -> np.ndarray:
    """[p − p_t; LEVER·ω'] with R·R_tᵀ = exp([ω]×) (world frame) and ω' = sin|ω|·ω/|ω| = vee of the
    skew part of R·R_tᵀ: the same zero as ω, first-order equal (cheaper than the log map);
    (N, 6), or (N, 3) without R_t."""
    e = p - p_t
    if R_t is None:
        return e
    E = R @ np.swapaxes(R_t, 1, 2)
    w = 0.5 * np.stack([E[:, 2, 1] - E[:, 1, 2], E[:, 0, 2] - E[:, 2, 0], E[:, 1, 0] - E[:, 0, 1]], axis=1)
    return np.concatenate([e, LEVER_M * w], axis=1)


def solve(kin: Kinematics, x: np.ndarray, p_t: np.ndarray, R_t: np.ndarray | None, q0: np.ndarray,
          options: IKOptions = IKOptions()) -> tuple[np.ndarray, np.ndarray]:
    """Damped Newton (LM) from q0 (N, n) toward each target; returns q and the final lever-
    weighted error norm (m), (N,).  Orientation is matched when R_t is given (6 × n), else
    position only (3 × n, least-norm steps for a redundant arm).  No wrapping or clipping."""
    q = np.array(q0, float, copy=True)
    n = q.shape[0]
    k = 3 if R_t is None else 6
    lam = np.full(n, options.damping)
    R, p, J = kin.pose_jacobian(x, q)
    e = pose_error(R, p, R_t, p_t)
    err = np.linalg.norm(e, axis=1)
    active = np.flatnonzero(err > options.tol_m)
    I = np.eye(kin.n_joints)
    for _ in range(options.iters):
        if active.size == 0:
            break
        Ja = J[active, :k].copy()
        if k == 6:
            Ja[:, 3:] *= LEVER_M
        JaT = np.swapaxes(Ja, 1, 2)
        JtJ = JaT @ Ja + lam[active, None, None] * I  # batched matmul: faster than einsum here
        step = np.linalg.solve(JtJ, JaT @ e[active][..., None])[..., 0]
        scale = np.minimum(1.0, options.max_step_rad / np.maximum(np.abs(step).max(axis=1), 1e-300))
        q_new = q[active] - step * scale[:, None]
        Rn, pn, Jn = kin.pose_jacobian(x, q_new)
        en = pose_error(Rn, pn, None if R_t is None else R_t[active], p_t[active])
        errn = np.linalg.norm(en, axis=1)
        better = errn < err[active]
        acc = active[better]
        q[acc], R[acc], p[acc], J[acc], e[acc], err[acc] = q_new[better], Rn[better], pn[better], Jn[better], en[better], errn[better]
        lam[acc] = np.maximum(lam[acc] / 10, options.damping)
        lam[active[~better]] *= 10
        active = active[(err[active] > options.tol_m) & (lam[active] < options.give_up_damping)]
    return q, err


def sigma_min(kin: Kinematics, x: np.ndarray, q: np.ndarray, orientation: bool = True) -> np.ndarray:
    """Smallest singular value of the lever-scaled pose Jacobian (m per rad), (N,)."""
    return sigma_min_of_jacobian(kin.pose_jacobian(x, q)[2], orientation)


def sigma_min_of_jacobian(J: np.ndarray, orientation: bool) -> np.ndarray:
    J = J.copy() if orientation else J[:, :3]
    if orientation:
        J[:, 3:] *= LEVER_M
    G = np.einsum("nik,njk->nij", J, J) if J.shape[1] <= J.shape[2] else np.einsum("nki,nkj->nij", J, J)
    return np.sqrt(np.clip(np.linalg.eigvalsh(G)[:, 0], 0, None))  # smallest singular value via the small Gram


def multistart(kin: Kinematics, x: np.ndarray, p_t: np.ndarray, R_t: np.ndarray | None, seeds: np.ndarray,
               options: IKOptions = IKOptions(), hint: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """IK from each row's hint (rows with a finite hint), else from each of `seeds` (S, n) in
    turn: the first solution converged within the limits, the controller's rule.  (q, ok).
    The seeds after the first are solved side by side in one batch (each row's solution from a
    seed does not depend on the other seeds, so the answer is the rule's; one batch instead of
    S sequential solves saves the per-iteration overhead on the few rows left)."""
    n = p_t.shape[0]
    q = np.full((n, kin.n_joints), np.nan)
    ok = np.zeros(n, bool)
    seeds = np.asarray(seeds, float).reshape(-1, kin.n_joints)
    starts = [] if hint is None else [(hint, True)]
    starts += [(np.broadcast_to(seeds[0], (n, kin.n_joints)), False)] if seeds.size else []
    for s0, own_turn in starts:  # the hint, then the first seed: most rows end here
        todo = np.flatnonzero(~ok & np.all(np.isfinite(s0), axis=1))
        if todo.size == 0:
            continue
        qs, err = solve(kin, x, p_t[todo], None if R_t is None else R_t[todo], s0[todo], options)
        good = _accept(kin, qs, err, own_turn)
        q[todo[good]], ok[todo[good]] = _turn(qs[good], own_turn), True
    todo = np.flatnonzero(~ok)
    if todo.size and seeds.shape[0] > 1:  # the other seeds, every (row, seed) pair in one batch
        S = seeds.shape[0] - 1
        rows = np.repeat(todo, S)
        q0 = np.tile(seeds[1:], (todo.size, 1))
        qs, err = solve(kin, x, p_t[rows], None if R_t is None else R_t[rows], q0, options)
        good = _accept(kin, qs, err, False).reshape(todo.size, S)
        first = np.argmax(good, axis=1)
        hit = good.any(axis=1)
        pick = np.arange(todo.size) * S + first
        q[todo[hit]], ok[todo[hit]] = _turn(qs[pick[hit]], False), True
    return q, ok


def _turn(q: np.ndarray, own_turn: bool) -> np.ndarray:
    """From a generic seed: the turn nearest zero (a hint keeps its own turn)."""
    return q if own_turn else (q + np.pi) % (2 * np.pi) - np.pi


def _accept(kin: Kinematics, q: np.ndarray, err: np.ndarray, own_turn: bool) -> np.ndarray:
    qs = _turn(q, own_turn)
    return (err <= 1e-9) & np.all((qs >= kin.lower) & (qs <= kin.upper), axis=1)
