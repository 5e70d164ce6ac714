"""The real-coded genetic algorithm of seed 001 (section III), for side-by-side comparison.

Faithful to the paper: real coding inside the bounds (eq. 16), fitness F = A/J with J the
sum of squared 3-D errors (eqs. 17–19), elitism plus fitness-proportional (roulette)
reproduction (eq. 20), arithmetic crossover with λ ~ U[0,1] (eq. 21), dynamic
(non-uniform) mutation δ(k, y) = y·r·(1 − k/T)^b (eqs. 22–23); population 100, crossover
probability 0.85, mutation probability 0.1, at most T = 10000 generations, stopping early
when the best individual has not improved for `stall` generations.  Eq. 22 prints the
full range (q^U − q^L) as the step bound; we use Michalewicz's form (q^U − q, q − q^L),
which the paper cites [13] and which keeps every gene inside its bounds.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class GAOptions:
    population: int = 100
    crossover: float = 0.85
    mutation: float = 0.1
    generations: int = 10000
    nonuniformity: float = 2.0  # b of eq. 23
    elite: int = 2
    stall: int = 1000
    scale_A: float = 1.0  # A of eq. 19
    seed: int = 0


@dataclass
class GAResult:
    x: np.ndarray
    cost: float  # J, m²
    generations: int
    elapsed_s: float
    history: np.ndarray  # best J per generation


def minimise(batch_cost: Callable[[np.ndarray], np.ndarray], lower: np.ndarray, upper: np.ndarray,
             options: GAOptions = GAOptions()) -> GAResult:
    """Minimise J(x) in the box by the paper's GA.  `batch_cost` (N,d) -> (N,) evaluates a
    whole population in one call (invalid individuals: inf)."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(options.seed)
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    N, d, T = options.population, lo.size, options.generations
    pop = rng.uniform(lo, hi, (N, d))  # step 1
    J = batch_cost(pop)
    best_hist = []
    best_J, best_x, since = np.inf, pop[0].copy(), 0
    k = 0
    for k in range(T):
        J = np.where(np.isfinite(J), J, np.inf)
        i_best = int(np.argmin(J))
        if J[i_best] < best_J * (1 - 1e-12):
            best_J, best_x, since = float(J[i_best]), pop[i_best].copy(), 0
        else:
            since += 1
        best_hist.append(best_J)
        if since >= options.stall:
            break
        F = np.where(np.isfinite(J), options.scale_A / np.maximum(J, 1e-300), 0.0)  # eq. 19
        elite = np.argsort(J)[:options.elite]  # step 4: elitism ...
        p = F / F.sum() if F.sum() > 0 else np.full(N, 1.0 / N)  # ... and roulette reproduction (eq. 20)
        rest = N - options.elite
        parents = pop[rng.choice(N, size=rest, p=p)]
        # step 5: arithmetic crossover of consecutive pairs (eq. 21)
        n_pairs = rest // 2
        a, b = parents[0:2 * n_pairs:2], parents[1:2 * n_pairs:2]
        do = rng.uniform(size=n_pairs) < options.crossover
        lam = rng.uniform(size=(n_pairs, 1))
        ca = np.where(do[:, None], lam * a + (1 - lam) * b, a)
        cb = np.where(do[:, None], lam * b + (1 - lam) * a, b)
        children = np.vstack([ca, cb, parents[2 * n_pairs:]])
        # step 6: dynamic mutation (eqs. 22-23)
        mut = rng.uniform(size=children.shape) < options.mutation
        tau = rng.integers(0, 2, size=children.shape)
        shrink = rng.uniform(size=children.shape) * (1 - k / T) ** options.nonuniformity
        up = children + (hi - children) * shrink
        down = children - (children - lo) * shrink
        children = np.where(mut, np.where(tau == 0, up, down), children)
        pop = np.vstack([pop[elite], children])
        J = np.concatenate([J[elite], batch_cost(children)])
    return GAResult(x=best_x, cost=best_J, generations=k + 1, elapsed_s=time.perf_counter() - t0,
                    history=np.array(best_hist))


def fit_ga(model, data, options: GAOptions = GAOptions()):
    """A `least_squares.Fit` whose estimate is the GA's best individual (no gradient polish).

    The model must offer `batch_cost_fn(data)` (→ J of a population) and bounds `lower`/`upper` (the scanner does).
    Identifiability and covariance are evaluated at the GA's solution like for LM.
    """
    from pipeline.identify.identifiability import analyse
    from pipeline.identify.least_squares import Fit, covariance

    t0 = time.perf_counter()
    lo, hi = np.asarray(model.lower, float), np.asarray(model.upper, float)
    res = minimise(model.batch_cost_fn(data), lo, hi, options)
    x = model.nominal().copy()
    x[:lo.size] = res.x
    names = model.parameter_names()
    J = model.jacobian(x, data)
    Jf = J.reshape(-1, J.shape[-1])
    ident = analyse(Jf, names, None, getattr(model, "priority", lambda: None)())
    r0 = model.residuals(model.nominal(), data)
    r1 = model.residuals(x, data)
    m, p = Jf[:, ident.free].shape
    sigma = float(np.sqrt(np.sum(r1**2) / max(m - p, 1)))
    cov = covariance(Jf[:, ident.free], sigma)
    std = np.zeros_like(x)
    std[ident.free] = np.sqrt(np.clip(np.diag(cov), 0, None))
    return Fit(names=names, units=model.parameter_units(), nominal=model.nominal(), x=x, identifiability=ident,
               std=std, cov=cov, residuals_before=r0, residuals_after=r1, sigma=sigma,
               nfev=res.generations * options.population, elapsed_s=time.perf_counter() - t0,
               history=list(np.sqrt(res.history / max(r1.size, 1))))


def cross_validate_ga(model, data, k: int = 5, seed: int = 0, options: GAOptions = GAOptions()) -> np.ndarray:
    """Held-out residuals (n, residual_dim) m, each fold predicted by a GA fit on the others (the folds of
    `least_squares.cross_validate`: kept representative of the design, `folds.design_folds`)."""
    from pipeline.identify.folds import design_folds
    from pipeline.identify.model import n_rows, take
    from pipeline.identify.natural_groups import holdout_groups

    n = n_rows(data)
    out = np.full((n, model.residual_dim), np.nan)
    for test in design_folds(n, k, seed, holdout_groups(model, data), data):
        train = np.setdiff1d(np.arange(n), test)
        f = fit_ga(model, take(data, train), options)
        out[test] = model.residuals(f.x, take(data, test))
    return out
