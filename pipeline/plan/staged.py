"""Planning a touch campaign that lands although the robot is off (Bayesian, two stages).

Before calibration the robot's error is known only in size: the prior on the parameter error
(`prior_cov`: 1° per angle, 4 mm per length, 2.5° base yaw, wider than the paper's errors — the
tool orientation does not move a point tip).  Linearised at the planning model, a candidate's
predicted contact then has a tangential σ along each face axis, and its landing probability is
P(the true contact stays inside both edges) × P(the search starts outside the material).

Stage 1 picks, among the candidates most likely to land, one contact on every face and then
the I-optimal rest (`ioptimal`: the least average predicted 3-D tool-point variance over the
pool's contact configurations, which span the jig, given the prior).  A maximum-a-posteriori fit
of what landed (`map_fit`: least squares with the prior as extra residuals, so 10–15 contacts
already pin the base yaw) gives the model and posterior covariance that stage 2 is planned on:
a new candidate pool by the updated model's IK, kept where it lands with probability ≥ `p_land`,
then I-optimal given stage 1's information (greedy + Fedorov exchange).  Pure numpy/scipy
functions of (model, data).
"""

from __future__ import annotations

import numpy as np
import scipy.optimize
from scipy.special import ndtr

from pipeline.models import serial_arm
from pipeline.models.jig import Jig
from pipeline.models.serial_arm import SerialArm
from pipeline.plan import ioptimal
from pipeline.plan.doptimal import woodbury_update
from pipeline.plan.touch import TouchPool

ANGLE_SD, LENGTH_SD, BASE_YAW_SD = np.radians(1.0), 4e-3, np.radians(2.5)


def prior_cov(arm: SerialArm) -> np.ndarray:
    """Prior covariance (P×P, diagonal) of the parameter error before calibration (see module)."""
    names, units = arm.parameter_names(), arm.parameter_units()
    sd = np.array([ANGLE_SD if u == "rad" else LENGTH_SD for u in units])
    sd[names.index("base.rz")] = BASE_YAW_SD
    for k in ("tool.rz", "tool.ry", "tool.rx"):
        sd[names.index(k)] = 0.0
    return np.diag(sd**2)


def landing_probability(x: np.ndarray, cov: np.ndarray, jig: Jig, pool: TouchPool, standoff_m: float) -> np.ndarray:
    """P(land) per candidate under parameter covariance `cov` (linearised at x), (N,)."""
    _, J = serial_arm.tip_jacobian(x, pool.q_contact)  # (N, 3, P)
    var = np.einsum("nip,nip->ni", J @ cov, J)
    sd = np.sqrt(np.clip(var, 1e-30, None))
    n = pool.face.size
    other = np.array([f.other_axes() for f in jig.faces])[pool.face]
    lo = np.array([[f.extent[0][0], f.extent[1][0]] for f in jig.faces])[pool.face]
    hi = np.array([[f.extent[0][1], f.extent[1][1]] for f in jig.faces])[pool.face]
    t = np.take_along_axis(pool.target, other, axis=1)
    s_t = np.take_along_axis(sd, other, axis=1)
    p_t = np.prod(ndtr((hi - t) / s_t) - ndtr((lo - t) / s_t), axis=1)
    s_n = sd[np.arange(n), pool.axis]
    return p_t * ndtr((pool.travel - 1e-3) / s_n)  # the true face must lie beyond the start


def bayes_greedy(A: np.ndarray, m: int, info0: np.ndarray, allowed: np.ndarray | None = None) -> np.ndarray:
    """Greedy Bayesian D-optimal choice of m rows of A (N, k, P) (each already divided by its
    noise σ) given prior information `info0` (P×P): maximise log det(info0 + Σ AᵀA)."""
    N, k, _ = A.shape
    Minv = np.linalg.pinv(info0 + 1e-12 * np.trace(info0) * np.eye(info0.shape[0]), hermitian=True)
    chosen = np.zeros(N, bool) if allowed is None else ~np.asarray(allowed, bool)
    order: list[int] = []
    I = np.eye(k)
    for _ in range(min(m, int((~chosen).sum()))):
        gain = np.linalg.slogdet(I + np.einsum("nkp,pq,nlq->nkl", A, Minv, A))[1]
        gain[chosen] = -np.inf
        j = int(np.argmax(gain))
        chosen[j] = True
        order.append(j)
        Minv = woodbury_update(Minv, A[j])
    return np.array(order, int)


def touch_rows(x: np.ndarray, pool: TouchPool, sigma_m: float) -> np.ndarray:
    """Information rows (N, 1, P) of candidate contacts at the planning model x, per noise σ."""
    _, J = serial_arm.tip_jacobian(x, pool.q_contact)
    return J[np.arange(pool.face.size), pool.axis][:, None, :] / sigma_m


def map_fit(model, table: dict, cov0: np.ndarray, sigma_m: float, x0: np.ndarray | None = None):
    """Maximum-a-posteriori fit: residuals/σ stacked with the prior (x − x₀)/σ₀ over the
    parameters with a prior σ₀ > 0 (the rest stay at x₀).  Returns (x, posterior cov P×P)."""
    x0 = model.nominal() if x0 is None else np.asarray(x0, float)
    sd0 = np.sqrt(np.diag(cov0))
    free = sd0 > 0

    def unpack(z):
        x = x0.copy()
        x[free] = z
        return x

    def res(z):
        x = unpack(z)
        return np.concatenate([model.residuals(x, table).ravel() / sigma_m, (z - x0[free]) / sd0[free]])

    def jac(z):
        J = model.jacobian(unpack(z), table).reshape(-1, x0.size)[:, free] / sigma_m
        return np.vstack([J, np.diag(1 / sd0[free])])

    sol = scipy.optimize.least_squares(res, x0[free], jac=jac, method="lm", xtol=1e-12, ftol=1e-12)
    x = unpack(sol.x)
    Jf = jac(sol.x)
    post = np.zeros_like(cov0)
    post[np.ix_(free, free)] = np.linalg.inv(Jf.T @ Jf)
    return x, post


def _allowed(p: np.ndarray, p_min: float, at_least: int, face: np.ndarray | None = None, per_face: int = 3,
             p_floor: float = 0.5) -> np.ndarray:
    """Candidates landing with P ≥ p_min, else the `at_least` likeliest; with `face`, also the
    `per_face` likeliest of every face where P ≥ p_floor, so that those faces can be covered
    (under the prior no candidate reaches p_min, and without this the y faces were never planned;
    the 30 mm risers, P ≈ 0.43 under the prior, wait for stage 2)."""
    allowed = p >= p_min
    if allowed.sum() < at_least:
        allowed = np.zeros(p.size, bool)
        allowed[np.argsort(-p)[:at_least]] = True
    if face is not None:
        order = np.lexsort((-p, face))  # by face, likeliest first
        rank = np.arange(p.size) - np.searchsorted(face[order], face[order])
        best = np.zeros(p.size, bool)
        best[order[rank < per_face]] = True
        allowed |= best & (p >= p_floor)
    return allowed


def _select(x: np.ndarray, pool: TouchPool, m: int, info0: np.ndarray, keep: np.ndarray, allowed: np.ndarray,
            sigma_m: float, criterion: str, groups: np.ndarray | None) -> np.ndarray:
    """m candidates: I-optimal (`ioptimal.select`: mean 3-D tool-point variance over the pool's
    contact configurations, which span the jig) or Bayesian D-optimal greedy ("D")."""
    rows = touch_rows(x, pool, sigma_m)[:, :, keep]
    if criterion == "D":
        return bayes_greedy(rows, m, info0, allowed)
    _, G = serial_arm.tip_jacobian(x, pool.q_contact)
    return ioptimal.select(rows, m, info0, ioptimal.eval_matrix(G[:, :, keep]), allowed, groups).index


def plan_first_stage(nominal: SerialArm, jig: Jig, pool: TouchPool, m: int, sigma_m: float = 5e-5,
                     standoff_m: float = 0.04, p_min: float = 0.95, criterion: str = "I",
                     cover: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Stage 1: (indices into pool, their landing probabilities) under the prior: among the
    candidates landing with P ≥ p_min (else the 3m likeliest) and the likeliest few of every face,
    I-optimal given the prior, one contact on every face first (`cover`: the MAP update between
    the stages sees every face and axis)."""
    x = nominal.vector()
    cov0 = prior_cov(nominal)
    keep = np.diag(cov0) > 0
    p = landing_probability(x, cov0, jig, pool, standoff_m)
    allowed = _allowed(p, p_min, 3 * m, pool.face if cover else None)
    idx = _select(x, pool, m, np.diag(1 / np.diag(cov0)[keep]), keep, allowed, sigma_m, criterion,
                  pool.face if cover else None)
    return idx, p[idx]


def plan_next_stage(x: np.ndarray, cov: np.ndarray, jig: Jig, pool: TouchPool, m: int, sigma_m: float = 5e-5,
                    standoff_m: float = 0.04, p_min: float = 0.99, criterion: str = "I",
                    prior: np.ndarray | None = None, prior_weight: float = 1.0,
                    cover: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Stage 2: (indices into a pool planned on the updated model x, landing probabilities under
    the posterior `cov`) given what the earlier stages already know, among the candidates landing
    with P ≥ p_min (else the 2m likeliest) and the likeliest few of every face (`cover`: one
    contact on every face, as in stage 1): I-optimal (default) or D-optimal.  The final
    calibration has no prior: with `prior` (the stage-1 prior covariance) its information in
    cov⁻¹ is counted at `prior_weight` only."""
    keep = np.diag(cov) > 0
    p = landing_probability(x, cov, jig, pool, standoff_m)
    info0 = np.linalg.inv(cov[np.ix_(keep, keep)])
    if prior is not None and prior_weight != 1.0:
        info0 = info0 - (1 - prior_weight) * np.linalg.inv(prior[np.ix_(keep, keep)])
        info0 = 0.5 * (info0 + info0.T)
    face = pool.face if cover else None
    idx = _select(x, pool, m, info0, keep, _allowed(p, p_min, 2 * m, face), sigma_m, criterion, face)
    return idx, p[idx]
