"""Excitation trajectories for dynamics identification: finite Fourier series (Swevers et al.) within the
joints' position, velocity and acceleration limits, optimised for the condition number of the base
regressor, optionally free of self-collision.

Per joint j, harmonics l = 1…L of the base frequency ω = 2π / period (rad, rad/s, rad/s²; m for a
prismatic joint):

    q_j(t) = q0_j + s_j Σ_l [a_jl / (ωl) · sin(ωlt) − b_jl / (ωl) · cos(ωlt)]
    q̇_j(t) = s_j Σ_l [a_jl cos(ωlt) + b_jl sin(ωlt)],   q̈_j(t) = s_j Σ_l ωl [−a_jl sin(ωlt) + b_jl cos(ωlt)]

The last harmonic's coefficients are set so that Σ_l a_jl = 0 and Σ_l l·b_jl = 0: the trajectory starts
(and, being periodic, ends every period) at rest, so a robot can run it from standstill.  The shape
(a, b) is free; each joint's scale s_j and offset q0_j are then the largest amplitude that keeps the
joint within its limits (less a margin) on a dense grid, centred in its range — every shape is feasible,
and the optimiser searches shapes only.  The objective is the 2-norm condition number of the base
regressor (`pipeline.dynamics.base`, columns scaled to unit RMS) at `samples` points of one period.
Pure numpy; Pinocchio computes the regressor and, where the URDF has collision geometry it can load,
the self-collisions (`collision`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.dynamics import base as B
from pipeline.dynamics import design
from pipeline.dynamics.identify import structural_base
from pipeline.dynamics.rigid_body import RigidBody, regressor

GRID_PER_PERIOD = 4000  # the limits are enforced on this many points per period (and checked denser in tests)


@dataclass(frozen=True)
class Limits:
    """Per joint (J,): position lower / upper (rad, m), |velocity| and |acceleration| bounds, and the share
    of each range kept free (`margin`)."""

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    margin: float = 0.05


@dataclass(frozen=True)
class Fourier:
    """A feasible excitation: base period (s), coefficients a, b (J, L) with the rest conditions applied,
    per-joint scale s (J,) and offset q0 (J,)."""

    period: float
    a: np.ndarray
    b: np.ndarray
    scale: np.ndarray
    q0: np.ndarray

    def states(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, q̇, q̈) (T, J) at times t (s)."""
        return _series(self.period, self.a * self.scale[:, None], self.b * self.scale[:, None], self.q0, t)


def _series(period: float, a: np.ndarray, b: np.ndarray, q0: np.ndarray, t: np.ndarray):
    w = 2 * np.pi / period
    L = a.shape[1]
    wl = w * np.arange(1, L + 1)  # (L,)
    ph = np.asarray(t, float)[:, None] * wl[None]  # (T, L)
    s, c = np.sin(ph), np.cos(ph)
    q = q0[None] + s @ (a / wl).T - c @ (b / wl).T
    v = c @ a.T + s @ b.T
    acc = -(s * wl) @ a.T + (c * wl) @ b.T
    return q, v, acc


def at_rest(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(a, b) with the last harmonic set so that q̇(0) = q̈(0) = 0 (module docstring)."""
    a, b = np.array(a, float), np.array(b, float)
    L = a.shape[1]
    a[:, -1] = -a[:, :-1].sum(axis=1)
    b[:, -1] = -(b[:, :-1] * np.arange(1, L)).sum(axis=1) / L
    return a, b


def feasible(period: float, a: np.ndarray, b: np.ndarray, lim: Limits) -> Fourier:
    """The shape (a, b) (rest conditions applied) at the largest per-joint scale within `lim`, centred."""
    a, b = at_rest(a, b)
    t = np.linspace(0.0, period, GRID_PER_PERIOD, endpoint=False)
    q, v, acc = _series(period, a, b, np.zeros(a.shape[0]), t)
    keep = 1.0 - lim.margin
    span = np.ptp(q, axis=0)
    with np.errstate(divide="ignore"):
        s = np.min(np.stack([keep * (lim.upper - lim.lower) / span, keep * lim.velocity / np.abs(v).max(axis=0),
                             keep * lim.acceleration / np.abs(acc).max(axis=0)]), axis=0)
    s = np.where(np.isfinite(s), s, 0.0)
    q0 = 0.5 * (lim.upper + lim.lower) - s * 0.5 * (q.max(axis=0) + q.min(axis=0))
    return Fourier(period, a, b, s, q0)


@dataclass(frozen=True)
class Objective:
    """The condition number of the base regressor of `rb` (fitted joints `fit`, model `terms`) at `samples`
    points of one period; `collide(q) -> (T,) bool` flags self-collisions (None: not checked)."""

    rb: RigidBody
    fit: np.ndarray
    terms: design.Terms
    samples: int = 150
    collide: object = None

    def base(self) -> B.BaseSet:
        return structural_base(self.rb, self.fit, self.terms)

    def condition(self, f: Fourier, base: B.BaseSet) -> float:
        t = np.linspace(0.0, f.period, self.samples, endpoint=False)
        q, v, acc = f.states(t)
        X = design.matrix(regressor(self.rb, q, v, acc), v, acc, self.fit, self.terms)[:, :, base.independent]
        A = X.reshape(-1, base.rank)
        if self.collide is not None and np.any(self.collide(f.states(np.linspace(0, f.period, 4 * self.samples))[0])):
            return np.inf
        return B.condition_number(A)


def random_shape(J: int, L: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Random coefficients a, b (J, L), standard normal, decaying as 1/l (a smooth start)."""
    d = 1.0 / np.arange(1, L + 1)
    return rng.standard_normal((J, L)) * d, rng.standard_normal((J, L)) * d


def optimise(obj: Objective, lim: Limits, period: float, harmonics: int, starts: int = 3, iterations: int = 60,
             seed: int = 0, progress=None) -> tuple[Fourier, float, float]:
    """(best feasible excitation, its condition number, the condition number of the first random start): from
    `starts` random shapes, each improved by L-BFGS-B on log cond over the free coefficients (the last
    harmonic's follow from the rest conditions)."""
    from pipeline.blas import one_thread

    with one_thread():  # small matrices: one BLAS thread is faster than a contended pool
        return _optimise(obj, lim, period, harmonics, starts, iterations, seed, progress or (lambda s: None))


def _optimise(obj, lim, period, harmonics, starts, iterations, seed, say):
    import scipy.optimize

    rng = np.random.default_rng(seed)
    J, L = lim.lower.size, harmonics
    base = obj.base()

    def unpack(z):
        a = np.zeros((J, L))
        b = np.zeros((J, L))
        a[:, :-1] = z[:J * (L - 1)].reshape(J, L - 1)
        b[:, :-1] = z[J * (L - 1):].reshape(J, L - 1)
        return feasible(period, a, b, lim)

    def cost(z):
        c = obj.condition(unpack(z), base)
        return float(np.log(c)) if np.isfinite(c) else 50.0

    best, random_cond = None, None
    for k in range(starts):
        a0, b0 = random_shape(J, L, rng)
        z0 = np.concatenate([a0[:, :-1].ravel(), b0[:, :-1].ravel()])
        c0 = float(np.exp(cost(z0)))
        if random_cond is None:
            random_cond = c0
        res = scipy.optimize.minimize(cost, z0, method="L-BFGS-B", options={"maxiter": iterations, "eps": 1e-4})
        c = float(np.exp(res.fun))
        say(f"start {k + 1}/{starts}: condition number {c0:.1f} → {c:.1f}")
        if best is None or c < best[1]:
            best = (unpack(res.x), c)
    return best[0], best[1], random_cond
