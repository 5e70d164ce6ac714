"""The prior's scales chosen by the evidence (type-II maximum likelihood) of the linearised Gaussian model.

Model, linearised at a point x̄ with Jacobian J (m, p) and residuals r (m,), SI:

    r(x) ≈ r + J (x − x̄) + e,   e ~ N(0, σ² I)                    (measurement noise, σ² estimated)
    x_i ~ N(c_i, (s_f(i) · σ_prior,i)²)                              (a penalised parameter of family f)
    x_i ~ N(c_i, σ_prior,i²)                                         (an anchored one: registration, physics)

Each *family* f (a group of the model: joint offsets, origin translations, origin rotations, …) has its own
scale s_f multiplying the stated prior 1σ of its parameters (`pipeline.accuracy.prior`): automatic relevance
determination.  The scales and σ² maximise the marginal likelihood p(r | s, σ²) — the evidence — which
rewards fit and penalises the posterior volume given up, so unlike GCV it does not trade a handful of degrees of
freedom for a slightly smaller residual on a small sample.  MacKay's fixed point: with the posterior
A = JᵀJ/σ² + diag(π), π_i the prior precision, mean x*, and γ_i = 1 − π_i (A⁻¹)_ii the share of parameter i
the data determine,

    s_f² = Σ_{i∈f} ((x*_i − c_i)/σ_prior,i)² / Σ_{i∈f} γ_i,      σ² = ‖r + J(x* − x̄)‖² / (m − Σ_i γ_i).

The MAP objective of `shrinkage.map_solve` is Σ r² + Σ λ_i² (x_i − c_i)² with λ_i = σ √π_i.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SCALE_RANGE = (1e-3, 1e3)  # s_f is kept within these multiples of the stated prior 1σ
ITERATIONS = 200
LOOSE = 30.0  # the loose start of `maximise`: 30 × the stated prior 1σ
TOLERANCE = 1e-6
FAMILIES = "group"  # experimental: group | kind
SPREAD = None
FLOOR = False  # experimental: hyperprior spread of the families' log-scales  # relative change of every log-scale and of log σ² at which the fixed point stops


@dataclass(frozen=True)
class Evidence:
    scales: np.ndarray  # (F,) s_f: family prior 1σ over the stated prior 1σ
    sigma2: float  # noise variance (m²)
    log_evidence: float  # ln p(r | s, σ²) of the linearised model
    gamma: np.ndarray  # (p,) share of each parameter determined by the data (0 … 1)
    x: np.ndarray  # (p,) posterior mean of the linearised model
    lam: np.ndarray  # (p,) λ_i = σ √π_i of the MAP objective


def _posterior(J, r, xbar, centre, prec, sigma2):
    """(x*, A⁻¹, linearised residual at x*, log|A|) of the linearised Gaussian model."""
    A = J.T @ J / sigma2 + np.diag(prec)
    w, V = np.linalg.eigh(A)
    w = np.maximum(w, w.max() * 1e-14)
    Ai = (V / w) @ V.T
    x = xbar - Ai @ (J.T @ r / sigma2 + prec * (xbar - centre))
    return x, Ai, r + J @ (x - xbar), float(np.sum(np.log(w)))


def log_evidence(J, r, xbar, centre, prec, sigma2) -> float:
    """ln p(r | π, σ²) of the linearised Gaussian model (every parameter with a proper prior, π > 0)."""
    x, _, rl, logdet = _posterior(J, r, xbar, centre, prec, sigma2)
    m = r.size
    return float(-0.5 * (rl @ rl / sigma2 + np.sum(prec * (x - centre) ** 2)) - 0.5 * logdet
                 + 0.5 * np.sum(np.log(prec)) - 0.5 * m * np.log(2 * np.pi * sigma2))


def maximise(J: np.ndarray, r: np.ndarray, xbar: np.ndarray, centre: np.ndarray, weight: np.ndarray,
             family: np.ndarray, scales: np.ndarray | None = None, sigma2: float | None = None) -> Evidence:
    """Scales and σ² of greatest evidence (`climb`) from the given start, the stated prior and a loose one
    (`LOOSE` × the stated prior 1σ): the evidence can have a second maximum where every family collapses onto
    its nominal and the noise takes the whole misfit; the highest of the maxima reached is returned."""
    F = int(np.max(family)) + 1 if np.size(family) and np.max(family) >= 0 else 0
    starts = [(None if scales is None else np.asarray(scales, float), sigma2), (np.ones(F), None),
              (np.full(F, LOOSE), None)]
    return max((climb(J, r, xbar, centre, weight, family, s, v) for s, v in starts), key=lambda e: e.log_evidence)


def climb(J: np.ndarray, r: np.ndarray, xbar: np.ndarray, centre: np.ndarray, weight: np.ndarray,
          family: np.ndarray, scales: np.ndarray | None = None, sigma2: float | None = None) -> Evidence:
    """Scales and σ² of greatest evidence (module docstring) of the problem linearised at `xbar`.

    `J` (m, p), `r` (m,), `xbar`, `centre` (p,) SI; `weight` (p,) 1/σ_prior of each parameter; `family` (p,)
    int: the family of a penalised parameter (0 … F−1), −1 for an anchored one (its prior is its stated 1σ,
    not scaled); `scales`, `sigma2`: the start (default: the stated prior, the residual's mean square)."""
    J, r = np.asarray(J, float), np.asarray(r, float)
    family = np.asarray(family, int)
    F = int(family.max()) + 1 if family.size and family.max() >= 0 else 0
    s = np.ones(F) if scales is None else np.asarray(scales, float).copy()
    s2 = float(np.mean(r**2)) if sigma2 is None else float(sigma2)
    s2 = max(s2, 1e-30)
    m = r.size
    pen = family >= 0
    w2 = np.asarray(weight, float) ** 2

    def prec_of(s):
        return np.where(pen, w2 / np.where(pen, s[np.maximum(family, 0)] ** 2, 1.0), w2)

    for _ in range(ITERATIONS):
        prec = prec_of(s)
        x, Ai, rl, _ = _posterior(J, r, xbar, centre, prec, s2)
        gamma = np.clip(1.0 - prec * np.diag(Ai), 0.0, 1.0)
        u2 = w2 * (x - centre) ** 2
        new = s.copy()
        for f in range(F):
            g, e = gamma[family == f].sum(), u2[family == f].sum()
            new[f] = np.sqrt(e / g) if g > 1e-12 else SCALE_RANGE[0]
        new = np.clip(new, *SCALE_RANGE)
        new_s2 = max(float(rl @ rl) / max(m - gamma.sum(), 1.0), 1e-30)
        done = np.all(np.abs(np.log(new / s)) < TOLERANCE) and abs(np.log(new_s2 / s2)) < TOLERANCE
        s, s2 = new, new_s2
        if done:
            break
    prec = prec_of(s)
    x, Ai, _, _ = _posterior(J, r, xbar, centre, prec, s2)
    gamma = np.clip(1.0 - prec * np.diag(Ai), 0.0, 1.0)
    return Evidence(s, s2, log_evidence(J, r, xbar, centre, prec, s2), gamma, x, np.sqrt(s2 * prec))


def families_of(model, idx: np.ndarray, w: np.ndarray, per_family: bool = True) -> tuple[np.ndarray, list[str]]:
    """(family index (len(idx),) of each estimated parameter — −1 for an unpenalised one — , family names): the
    model's groups (registration aside) with `per_family`, else one family 'all'."""
    names = model.parameter_names()
    group = {n: g for g, v in (model.groups() if hasattr(model, "groups") else {}).items() for n in v}
    if FAMILIES == "kind":
        from pipeline.accuracy.prior import kind_of

        group = {n: kind_of(n, u) for n, u in zip(names, model.parameter_units())}
    labels: list[str] = []
    fam = np.full(len(idx), -1)
    for j, i in enumerate(idx):
        if w[i] <= 0:
            continue
        g = group.get(names[i], "other") if per_family else "all"
        if g not in labels:
            labels.append(g)
        fam[j] = labels.index(g)
    return fam, labels


def shrink_evidence(model, data, prior_sigma: np.ndarray, x0: np.ndarray, fixed: tuple[str, ...] = (),
                    per_family: bool = True, progress=None, extra: tuple[str, ...] = (), rounds: int = 4):
    """MAP estimate with the prior's scales (one per family of the model with `per_family`, else one) and the
    noise σ² of greatest evidence (module docstring); the registration and `extra` anchored at `x0` with their
    stated prior.  Solve, linearise, maximise the evidence, again until the weights settle (at most `rounds`
    solves after the first).  Returns `shrinkage.Shrunk` with `lam` the MAP weights per parameter."""
    from pipeline.identify.shrinkage import Shrunk, _anchor, _implausible, _penalty, map_solve

    prior_sigma = np.asarray(prior_sigma, float)
    nominal = np.asarray(model.nominal(), float)
    free, w = _penalty(model, prior_sigma, fixed, extra)
    anchor = _anchor(model, prior_sigma, fixed, extra)
    centre = np.where(w > 0, nominal, np.asarray(x0, float))
    idx = np.flatnonzero(free)
    fam, labels = families_of(model, idx, w, per_family)
    weight = np.where(fam >= 0, w[idx], anchor[idx])
    keep = weight > 0  # a free parameter with neither penalty nor anchor (none in practice) is left unpenalised
    x = np.asarray(x0, float).copy()
    r0 = np.asarray(model.residuals(x, data), float).ravel()
    m = r0.size
    # the first linearisation: a solve with the stated prior's weights at the registration-only residual
    lam_prev = float(np.sqrt(np.mean(r0**2))) * weight
    x = map_solve(model, data, x, idx, lam_prev, centre)
    ev, solves = None, 1
    while True:
        r = np.asarray(model.residuals(x, data), float).ravel()
        J = np.asarray(model.jacobian(x, data), float).reshape(m, -1)[:, idx]
        ev = maximise(J[:, keep], r, x[idx][keep], centre[idx][keep], weight[keep], fam[keep],
                      None if ev is None else ev.scales, None if ev is None else ev.sigma2)
        if FLOOR and per_family:
            one = maximise(J[:, keep], r, x[idx][keep], centre[idx][keep], weight[keep], np.where(fam[keep] >= 0, 0, -1))
            global SCALE_RANGE
            old = SCALE_RANGE
            SCALE_RANGE = (float(one.scales[0]), old[1])
            ev = maximise(J[:, keep], r, x[idx][keep], centre[idx][keep], weight[keep], fam[keep],
                          np.maximum(ev.scales, one.scales[0]), ev.sigma2)
            SCALE_RANGE = old
        if SPREAD is not None and per_family:
            ev = pooled(J[:, keep], r, x[idx][keep], centre[idx][keep], weight[keep], fam[keep], ev, SPREAD)
        lam = np.zeros(idx.size)
        lam[keep] = ev.lam
        if progress is not None:
            progress("shrinkage by the evidence: σ " + f"{np.sqrt(ev.sigma2) * 1e3:.4g} mm, scales "
                     + ", ".join(f"{lb} {s:.3g}" for lb, s in zip(labels, ev.scales))
                     + f", {ev.gamma.sum():.1f} effective parameters")
        settled = lam_prev is not None and np.all(np.abs(np.log((lam + 1e-300) / (lam_prev + 1e-300))) < 0.05)
        if settled or solves > rounds:
            break
        x = map_solve(model, data, x, idx, lam, centre)
        lam_prev, solves = lam, solves + 1
    lam_full = np.zeros(x.size)
    lam_full[idx] = lam_prev if lam_prev is not None else lam
    sigma = float(np.sqrt(ev.sigma2))
    mu = sigma / float(np.exp(np.mean(np.log(ev.scales)))) if ev.scales.size else np.inf
    rl = np.asarray(model.residuals(x, data), float).ravel()
    dof = float(ev.gamma.sum())
    score = m * float(rl @ rl) / max(m - dof, 1e-9) ** 2
    return Shrunk(x, mu, {mu: score}, dof, _implausible(model, x, idx, w, nominal), solves,
                  lam=lam_full, scales=dict(zip(labels, map(float, ev.scales))), log_evidence=ev.log_evidence,
                  multiple=mu / float(np.sqrt(np.mean(np.asarray(model.residuals(x0, data), float) ** 2))))


def pooled(J, r, xbar, centre, weight, family, start: Evidence, spread: float) -> Evidence:
    """Evidence maximised with the families' log-scales pulled toward their mean (a hyperprior
    log s_f ~ N(mean, `spread`²)): partial pooling between one scale and a free scale per family."""
    from scipy.optimize import minimize

    family = np.asarray(family, int)
    pen = family >= 0
    w2 = np.asarray(weight, float) ** 2
    F = start.scales.size

    def prec_of(ls):
        return np.where(pen, w2 * np.exp(-2 * ls[np.maximum(family, 0)]), w2)

    def obj(z):
        ls, lv = z[:F], z[F]
        pen_h = np.sum((ls - ls.mean()) ** 2) / (2 * spread**2)
        return -log_evidence(J, r, xbar, centre, prec_of(ls), np.exp(lv)) + pen_h

    z0 = np.r_[np.log(start.scales), np.log(start.sigma2)]
    lo, hi = np.log(SCALE_RANGE)
    res = minimize(obj, z0, method="L-BFGS-B", bounds=[(lo, hi)] * F + [(None, None)])
    ls, s2 = res.x[:F], float(np.exp(res.x[F]))
    prec = prec_of(ls)
    x, Ai, _, _ = _posterior(J, r, xbar, centre, prec, s2)
    gamma = np.clip(1.0 - prec * np.diag(Ai), 0.0, 1.0)
    return Evidence(np.exp(ls), s2, log_evidence(J, r, xbar, centre, prec, s2), gamma, x, np.sqrt(s2 * prec))
