"""The prior's scales chosen by the evidence (type-II maximum likelihood) of the linearised Gaussian model.

Model, linearised at a point x̄ with Jacobian J (m, p) and residuals r (m,), SI:

    r(x) ≈ r + J (x − x̄) + e,   e ~ N(0, σ² I)                    (measurement noise, σ² estimated)
    x_i ~ N(c_i, (s_f(i) · σ_prior,i)²)                              (a penalised parameter of family f)
    x_i ~ N(c_i, σ_prior,i²)                                         (an anchored one: registration, physics)

Each *family* f (a group of the model: joint offsets, origin translations, origin rotations, …) has its own
scale s_f multiplying the stated prior 1σ of its parameters (`pipeline.accuracy.prior`).  The scales and σ²
maximise the marginal likelihood p(r | s, σ²) — the evidence — which rewards fit and penalises the posterior
volume given up: unlike GCV it does not trade many degrees of freedom for a slightly smaller residual on a small
sample.  MacKay's fixed point: with the posterior A = JᵀJ/σ² + diag(π), π_i the prior precision, mean x*, and
γ_i = 1 − π_i (A⁻¹)_ii the share of parameter i the data determine,

    s_f² = Σ_{i∈f} ((x*_i − c_i)/σ_prior,i)² / Σ_{i∈f} γ_i,      σ² = ‖r + J(x* − x̄)‖² / (m − Σ_i γ_i).

Two stages (`scales`): the common scale s₀ of every family together (one scale: the stated priors' proportions
kept), then each family's own scale, never below s₀.  A family may be given more room than the rest where its
own evidence asks for it (TIAGo's origin translations); it is not made tighter than the rest: the evidence of a
family the rows barely determine is flat below s₀ and its fixed point slides toward zero ("pruning"), which on a
few dozen rows says the family is not determined, not that it is built more precisely than its stated
tolerance's proportion to the others.  The MAP objective of `shrinkage.map_solve` is Σ r² + Σ λ_i² (x_i − c_i)²
with λ_i = σ √π_i.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import LinAlgError, cho_factor, cho_solve

SCALE_RANGE = (1e-3, 1e3)  # s_f is kept within these multiples of the stated prior 1σ
LOOSE = 30.0  # the loose start of `maximise`: 30 × the stated prior 1σ
ITERATIONS = 300
TOLERANCE = 1e-4  # change of every log-scale and of log σ² at which the fixed point stops


@dataclass(frozen=True)
class Evidence:
    scales: np.ndarray  # (F,) s_f: family prior 1σ over the stated prior 1σ
    sigma2: float  # noise variance (m²)
    log_evidence: float  # ln p(r | s, σ²) of the linearised model
    gamma: np.ndarray  # (p,) share of each parameter determined by the data (0 … 1)
    x: np.ndarray  # (p,) posterior mean of the linearised model
    lam: np.ndarray  # (p,) λ_i = σ √π_i of the MAP objective
    common: float = float("nan")  # s₀: the one scale of every family together (`scales`)


def _posterior(J, r, xbar, centre, prec, sigma2):
    """(x*, diag A⁻¹, linearised residual at x*, log|A|) of the linearised Gaussian model."""
    A = J.T @ J / sigma2 + np.diag(prec)
    b = J.T @ r / sigma2 + prec * (xbar - centre)
    try:
        c = cho_factor(A)
        step, diag = cho_solve(c, b), np.diag(cho_solve(c, np.eye(A.shape[0])))
        logdet = 2.0 * float(np.sum(np.log(np.diag(c[0]))))
    except LinAlgError:  # numerically singular: the eigen-decomposition, tiny eigenvalues raised
        w, V = np.linalg.eigh(A)
        w = np.maximum(w, w.max() * 1e-14)
        step, diag, logdet = V @ ((V.T @ b) / w), np.sum(V**2 / w, axis=1), float(np.sum(np.log(w)))
    x = xbar - step
    return x, diag, r + J @ (x - xbar), logdet


def log_evidence(J, r, xbar, centre, prec, sigma2) -> float:
    """ln p(r | π, σ²) of the linearised Gaussian model (every parameter with a proper prior, π > 0)."""
    x, _, rl, logdet = _posterior(J, r, xbar, centre, prec, sigma2)
    return float(-0.5 * (rl @ rl / sigma2 + np.sum(prec * (x - centre) ** 2)) - 0.5 * logdet
                 + 0.5 * np.sum(np.log(prec)) - 0.5 * r.size * np.log(2 * np.pi * sigma2))


def climb(J, r, xbar, centre, weight, family, scales=None, sigma2=None, floor: float = SCALE_RANGE[0]) -> Evidence:
    """MacKay's fixed point (module docstring) from `scales`, `sigma2` (default: the stated prior, the residual's
    mean square) to a maximum of the evidence, every scale kept within [`floor`, SCALE_RANGE[1]].

    `J` (m, p), `r` (m,), `xbar`, `centre` (p,) SI; `weight` (p,) 1/σ_prior of each parameter (> 0); `family`
    (p,) int: the family of a penalised parameter (0 … F−1), −1 for an anchored one (its prior is its stated 1σ)."""
    J, r, family = np.asarray(J, float), np.asarray(r, float), np.asarray(family, int)
    F = int(family.max()) + 1 if family.size and family.max() >= 0 else 0
    lo, hi = max(floor, SCALE_RANGE[0]), SCALE_RANGE[1]
    s = np.clip(np.ones(F) if scales is None else np.asarray(scales, float), lo, hi)
    s2 = max(float(np.mean(r**2)) if sigma2 is None else float(sigma2), 1e-30)
    pen, w2 = family >= 0, np.asarray(weight, float) ** 2
    members = [family == f for f in range(F)]

    def prec_of(s):
        return np.where(pen, w2 / s[np.maximum(family, 0)] ** 2, w2) if F else w2

    for _ in range(ITERATIONS):
        prec = prec_of(s)
        x, diag, rl, _ = _posterior(J, r, xbar, centre, prec, s2)
        gamma = np.clip(1.0 - prec * diag, 0.0, 1.0)
        u2 = w2 * (x - centre) ** 2
        new = np.array([np.sqrt(u2[k].sum() / gamma[k].sum()) if gamma[k].sum() > 1e-12 else lo for k in members])
        new = np.clip(new, lo, hi)
        new_s2 = max(float(rl @ rl) / max(r.size - gamma.sum(), 1.0), 1e-30)
        done = np.all(np.abs(np.log(new / s)) < TOLERANCE) and abs(np.log(new_s2 / s2)) < TOLERANCE
        s, s2 = new, new_s2
        if done:
            break
    prec = prec_of(s)
    x, diag, _, _ = _posterior(J, r, xbar, centre, prec, s2)
    gamma = np.clip(1.0 - prec * diag, 0.0, 1.0)
    return Evidence(s, s2, log_evidence(J, r, xbar, centre, prec, s2), gamma, x, np.sqrt(s2 * prec))


def maximise(J, r, xbar, centre, weight, family, scales=None, sigma2=None, floor: float = SCALE_RANGE[0]
             ) -> Evidence:
    """`climb` from the given start, or — without one — from the stated prior and from a loose one (`LOOSE` ×
    the stated 1σ): the evidence can have a second maximum where every family collapses onto its nominal and the
    noise takes the whole misfit; the highest of the maxima reached is returned."""
    F = int(np.max(family)) + 1 if np.size(family) and np.max(family) >= 0 else 0
    starts = [(scales, sigma2)] if scales is not None else [(np.ones(F), None), (np.full(F, LOOSE), None)]
    return max((climb(J, r, xbar, centre, weight, family, s, v, floor) for s, v in starts),
               key=lambda e: e.log_evidence)


def scales(J, r, xbar, centre, weight, family, start: Evidence | None = None) -> Evidence:
    """The two stages of the module docstring: s₀ of every family together, then each family's own scale
    ≥ s₀ (warm from `start`, the previous linearisation's answer)."""
    family = np.asarray(family, int)
    one = maximise(J, r, xbar, centre, weight, np.where(family >= 0, 0, -1),
                   None if start is None else np.array([start.common]), None if start is None else start.sigma2)
    s0 = float(one.scales[0]) if one.scales.size else 1.0
    F = int(family.max()) + 1 if family.size and family.max() >= 0 else 0
    warm = np.full(F, s0) if start is None else np.maximum(start.scales, s0)
    ev = climb(J, r, xbar, centre, weight, family, warm, one.sigma2, floor=s0)
    return Evidence(ev.scales, ev.sigma2, ev.log_evidence, ev.gamma, ev.x, ev.lam, s0)


def families_of(model, idx: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """(family index (len(idx),) of each estimated parameter — −1 for an unpenalised one —, family names): the
    model's groups, the registration aside."""
    names = model.parameter_names()
    group = {n: g for g, v in (model.groups() if hasattr(model, "groups") else {}).items() for n in v}
    labels: list[str] = []
    fam = np.full(len(idx), -1)
    for j, i in enumerate(idx):
        if w[i] > 0:
            g = group.get(names[i], "other")
            labels += [g] if g not in labels else []
            fam[j] = labels.index(g)
    return fam, labels


def shrink_evidence(model, data, prior_sigma: np.ndarray, x0: np.ndarray, fixed: tuple[str, ...] = (),
                    progress=None, extra: tuple[str, ...] = (), rounds: int = 4):
    """MAP estimate with the prior's scales and the noise σ² of greatest evidence (module docstring); the
    registration and `extra` anchored at `x0` (e.g. the registration-only fit) with their stated prior.  A first
    solve with the stated prior at the registration-only residual, then: linearise, choose the scales, solve,
    until the weights move less than 5 % (at most `rounds` solves after the first).  Returns `shrinkage.Shrunk`
    (`lam` the MAP weights per parameter, `scales` per family, μ = σ / s₀)."""
    from pipeline.identify.shrinkage import Shrunk, _anchor, _implausible, _penalty, map_solve

    prior_sigma = np.asarray(prior_sigma, float)
    nominal = np.asarray(model.nominal(), float)
    free, w = _penalty(model, prior_sigma, fixed, extra)
    anchor = _anchor(model, prior_sigma, fixed, extra)
    centre = np.where(w > 0, nominal, np.asarray(x0, float))
    idx = np.flatnonzero(free)
    fam, labels = families_of(model, idx, w)
    weight = np.where(fam >= 0, w[idx], anchor[idx])
    keep = weight > 0  # a free parameter with neither penalty nor anchor (none in practice) stays unpenalised
    x = np.asarray(x0, float).copy()
    r0 = np.asarray(model.residuals(x, data), float).ravel()
    m = r0.size
    lam_used = float(np.sqrt(np.mean(r0**2))) * weight
    x = map_solve(model, data, x, idx, lam_used, centre)
    ev, solves = None, 1
    while True:
        r = np.asarray(model.residuals(x, data), float).ravel()
        J = np.asarray(model.jacobian(x, data), float).reshape(m, -1)[:, idx]
        ev = scales(J[:, keep], r, x[idx][keep], centre[idx][keep], weight[keep], fam[keep], ev)
        lam = np.zeros(idx.size)
        lam[keep] = ev.lam
        if progress is not None:
            progress(f"shrinkage by the evidence: σ {np.sqrt(ev.sigma2) * 1e3:.4g} mm, common scale {ev.common:.3g}, "
                     + ", ".join(f"{lb} {s:.3g}" for lb, s in zip(labels, ev.scales))
                     + f", {ev.gamma.sum():.1f} effective parameters")
        if np.all(np.abs(np.log((lam + 1e-300) / (lam_used + 1e-300))) < 0.05) or solves > rounds:
            break
        x = map_solve(model, data, x, idx, lam, centre)
        lam_used, solves = lam, solves + 1
    lam_full = np.zeros(x.size)
    lam_full[idx] = lam_used
    mu = float(np.sqrt(ev.sigma2)) / ev.common
    scale = float(np.sqrt(np.mean(r0**2)))
    rl = np.asarray(model.residuals(x, data), float).ravel()
    dof = float(ev.gamma.sum())
    score = m * float(rl @ rl) / max(m - dof, 1e-9) ** 2  # GCV at the estimate: what the physics choice compares
    return Shrunk(x, mu, {mu: score}, dof, _implausible(model, x, idx, w, nominal), solves, lam=lam_full,
                  scales=dict(zip(labels, map(float, ev.scales))), log_evidence=ev.log_evidence,
                  multiple=mu / scale if scale > 0 else float("nan"))
