"""Nonlinear least-squares identification for any `MeasurementModel`.

`fit` follows seed 000 section 5: iterate on the full nonlinear model from the nominal
start (not one linearised step), with dependent parameters eliminated by the rank test of
`identifiability`, solved by `scipy.optimize.least_squares` with Jacobian-based scaling.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import least_squares

from pipeline.identify.folds import kfold_indices  # noqa: F401 — re-exported: the seeded split the folds repair
from pipeline.blas import single_threaded
from pipeline.identify.identifiability import RANK_TOL, Identifiability, analyse
from pipeline.identify.model import MeasurementModel, Table, n_rows, take, uncalibrated


@dataclass(frozen=True)
class FitOptions:
    """Solver settings.  `loss` as in scipy ('linear', 'huber', 'soft_l1', ...); `f_scale` in m."""

    loss: str = "linear"
    f_scale: float = 1e-4
    fixed: tuple[str, ...] = ()
    max_nfev: int | None = None
    rank_tol: float = RANK_TOL
    x0: np.ndarray | None = None
    before: bool = True  # compute the "before" residuals at the model's uncalibrated parameters
    prior_sigma: np.ndarray | None = None  # (P,) SI: each parameter's prior 1σ (default: accuracy.prior's defaults)
    physical: bool = True  # refuse (hold at 0) terms the model says cannot be negative, estimated negative
    retest: bool = True  # re-test the rank at each solution (False: one solve over the columns free at the start)


@dataclass
class Fit:
    """Result of an identification (fields in SI units)."""

    names: list[str]
    units: list[str]
    nominal: np.ndarray
    x: np.ndarray
    identifiability: Identifiability
    std: np.ndarray  # 1σ per parameter, 0 for fixed ones
    cov: np.ndarray  # covariance of the free parameters (free × free)
    residuals_before: np.ndarray  # (n, k) m
    residuals_after: np.ndarray  # (n, k) m
    sigma: float  # residual standard deviation, m (dof-corrected)
    nfev: int
    elapsed_s: float
    history: list[float] = field(default_factory=list)  # cost (RMS, m) at each evaluation
    converged: bool = True  # False: the last solve stopped at FitOptions.max_nfev, not at a tolerance

    @property
    def free(self) -> np.ndarray:
        return self.identifiability.free

    @property
    def rms_before(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_before**2)))

    @property
    def rms_after(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_after**2)))


def _flat_jac(model: MeasurementModel, x: np.ndarray, data: Table) -> np.ndarray:
    J = model.jacobian(x, data)
    return J.reshape(-1, J.shape[-1])


@single_threaded
def fit(model: MeasurementModel, data: Table, options: FitOptions = FitOptions()) -> Fit:
    """Identify the model's parameters from `data` (see module docstring).

    A model may offer ``without(names)``: the same model lacking those of `names` it can drop — terms
    held at 0 that are then no-ops (a `TreePointModel`'s physics terms: rigid), so every residual and
    every other parameter's Jacobian column is unchanged.  Parameters held fixed at 0 are then fitted
    on the smaller model (its chains shorter, its Jacobian narrower) and the result widened back."""
    f = _fit_once(model, data, options)
    hook = getattr(model, "nonnegative", None)
    if hook is None or not options.physical:
        return f
    allowed = set(hook())  # terms that cannot be negative (a compliance): refused, held at 0, the rest refitted
    refused: list[str] = []
    # each refit starts at the fit before it, the refused terms at 0: a bounded solve per rank round.  Near a
    # dependency, a round that re-fixes a parameter restarts far off (its start value) and Levenberg–Marquardt
    # crawls along the flat valley (thousands of evaluations for the 10⁻⁹ of cost it leaves); the next round,
    # from where the bounded solve stopped, reaches the same minimum
    budget = options.max_nfev if options.max_nfev is not None else REFIT_NFEV
    for _ in range(4):
        neg = [n for i, n in enumerate(f.names) if n in allowed and f.free[i] and f.x[i] < 0]
        if not neg:
            break
        refused += neg
        x0 = np.where(np.isin(f.names, refused), 0.0, f.x)
        f = replace(_fit_once(model, data, replace(options, fixed=tuple(options.fixed) + tuple(refused), x0=x0,
                                                   before=False, max_nfev=budget)),
                    nominal=f.nominal, residuals_before=f.residuals_before)
    for n in refused:
        f.identifiability.reasons[f.names.index(n)] = NEGATIVE
    return f


REFIT_NFEV = 100  # residual evaluations per solve of a refit after negative terms are refused
NEGATIVE = "held at 0: estimated negative, which no physical stiffness gives (the term absorbed something else)"


def _fit_once(model: MeasurementModel, data: Table, options: FitOptions) -> Fit:
    """One identification (`fit` without its refusal of negative terms)."""
    small = _without_fixed(model, options)
    if small is not None:
        return _widened(model, data, options, small)
    return _fit(model, data, options)[0]


def _without_fixed(model: MeasurementModel, options: FitOptions):
    """The model without the parameters `options` holds fixed at 0 that it can drop, or None."""
    hook = getattr(model, "without", None)
    if hook is None or not options.fixed:
        return None
    names = model.parameter_names()
    fixed = set(options.fixed)
    if fixed - set(names):  # `_fit` says which are unknown
        return None
    if options.x0 is not None:
        x0 = np.asarray(options.x0, float)
        drop = tuple(n for n, v in zip(names, x0) if n in fixed and v == 0.0)
    else:  # the start is the model's nominal or its data-dependent guess: a droppable term starts at 0 there
        drop = tuple(n for n in names if n in fixed)
    small = hook(drop) if drop else model
    if small is model or type(small) is not type(model):  # a wrapper that passes attributes on: not its hook
        return None
    return small if len(small.parameter_names()) < len(names) else None


def _widened(model: MeasurementModel, data: Table, options: FitOptions, small) -> Fit:
    """`fit` of `model` through `small` (`model` without terms held fixed at 0), widened back to
    `model`'s parameters: the dropped ones held at 0, fixed by the user.  The rank tests run on
    `model`'s Jacobian (its fixed columns shape the pivoted QR's rounding), so the outcome is the
    one `fit` on `model` itself reaches, to the last bit."""
    t0 = time.perf_counter()
    names = model.parameter_names()
    index = {n: i for i, n in enumerate(names)}
    sub = small.parameter_names()
    keep = np.array([index[n] for n in sub], int)
    kept = set(sub)
    cut = lambda a: None if a is None else np.asarray(a, float)[keep]  # noqa: E731
    opts = replace(options, fixed=tuple(n for n in options.fixed if n in kept), x0=cut(options.x0),
                   prior_sigma=cut(options.prior_sigma), before=False)
    f, ident = _fit(small, data, opts, (model, keep, np.array([n in set(options.fixed) for n in names])))
    # "before": as `_fit` computes it on the whole model (its registration-only fit is itself reduced)
    r0 = model.residuals(uncalibrated(model, data), data) if options.before else f.residuals_before
    P = len(names)
    x, nominal, std = np.zeros(P), np.zeros(P), np.zeros(P)
    x[keep], nominal[keep], std[keep] = f.x, f.nominal, f.std
    return Fit(names=names, units=model.parameter_units(), nominal=nominal, x=x, identifiability=ident, std=std,
               cov=f.cov, residuals_before=r0, residuals_after=f.residuals_after, sigma=f.sigma, nfev=f.nfev,
               elapsed_s=time.perf_counter() - t0, history=f.history, converged=f.converged)


def _fit(model: MeasurementModel, data: Table, options: FitOptions, whole=None):
    """`fit` on the model as it is: (Fit, its rank test).  `whole`: (the model `model` was cut from, the
    index of each of `model`'s parameters in it, its fixed mask) — the rank tests then run on the
    whole model's Jacobian at the widened x and the rank test returned is the whole model's."""
    t0 = time.perf_counter()
    names = model.parameter_names()
    if options.x0 is not None:
        x0 = np.asarray(options.x0, float)
    elif hasattr(model, "initial_guess"):  # optional hook: a data-dependent start (e.g. a closed-form registration)
        x0 = np.asarray(model.initial_guess(data), float)
    else:
        x0 = model.nominal()
    unknown = set(options.fixed) - set(names)
    if unknown:
        raise ValueError(f"cannot fix unknown parameters: {sorted(unknown)}")
    fixed = np.array([n in options.fixed for n in names])
    priority = getattr(model, "priority", lambda: None)()
    # "before": the uncalibrated system (a model's registration-only fit calls `fit` with before=False)
    r0 = model.residuals(uncalibrated(model, data) if options.before else x0, data)
    history: list[float] = []
    x = x0.copy()

    def rank(J: np.ndarray | None, x: np.ndarray, fx: np.ndarray):
        """(rank test over `model`'s parameters, the same over the whole model's) at x, `fx` held fixed."""
        if whole is None:
            a = analyse(_flat_jac(model, x, data) if J is None else J, names, fx, priority, options.rank_tol)
            return a, a
        big, keep, bfixed = whole
        xw = np.zeros(bfixed.size)
        xw[keep] = x
        fw = bfixed.copy()
        fw[keep] |= fx
        key = xw.tobytes()
        if key not in jw:
            jw.clear()
            jw[key] = _whole_jacobian(model, big, keep, x, xw, data, J)
        a = analyse(jw[key], big.parameter_names(), fw, getattr(big, "priority", lambda: None)(), options.rank_tol)
        return Identifiability(free=a.free[keep], reasons={}, pivots=a.pivots, order=a.order), a

    jw: dict = {}
    ident, ident_w = rank(None, x0, fixed)
    nfev = 0
    # Seed 000 re-eliminates dependent parameters at every iteration (eq. 57): a dependency
    # that holds only at the nominal geometry (e.g. a tool tip exactly on the last joint
    # axis) is lifted once the estimate moves off it.  Re-test at each solution until the
    # free set is stable.  Parameters that the re-test fixes go back to their start value,
    # so a fixed parameter always reads as fixed.
    # A parameter the re-test frees became identifiable only through the estimate's move off
    # the nominal geometry (a lever of its deviation, often mm): it stays free only if the data
    # determine it better than its prior does (`weakly_freed`); else a step along it is noise
    # and nonlinearity (UR10, tool point on the last axis: wrist rotations freed at 4 mm lever
    # moved by radians and broke the model away from the data).
    for round_ in range(4):
        sol = _solve(model, data, x, ident.free, options, history)
        nfev += int(sol.nfev)
        x = x.copy()
        x[ident.free] = sol.x
        if not options.retest:
            break
        J = _flat_jac(model, x, data)
        (again, again_w), weak = rank(J, x, fixed), np.zeros(x.size, bool)
        for _ in range(x.size):  # fixing a weak one may free its dependent partner: test that too
            more = weakly_freed(model, data, x, ident.free, again.free, J, options.prior_sigma) & ~weak
            if not more.any():
                break
            weak |= more
            again, again_w = rank(J, x, fixed | weak)
        for i in np.flatnonzero(weak):
            again.reasons[int(i)] = "determined no better than its prior (freed only off the nominal geometry)"
            if whole is not None:
                again_w.reasons[int(whole[1][i])] = again.reasons[int(i)]
        if np.array_equal(again.free, ident.free) or round_ == 3:
            break
        ident, ident_w = again, again_w
        x[~ident.free] = x0[~ident.free]
    free = ident.free
    r1 = model.residuals(x, data)
    Jf = _flat_jac(model, x, data)[:, free]
    m, p = Jf.shape
    sigma = float(np.sqrt(np.sum(r1**2) / max(m - p, 1)))
    cov = covariance(Jf, sigma)
    std = np.zeros_like(x)
    std[free] = np.sqrt(np.clip(np.diag(cov), 0, None))
    return Fit(names=names, units=model.parameter_units(), nominal=x0, x=x, identifiability=ident,
               std=std, cov=cov, residuals_before=r0, residuals_after=r1, sigma=sigma, nfev=nfev,
               elapsed_s=time.perf_counter() - t0, history=history, converged=bool(sol.status != 0)), ident_w


def _whole_jacobian(small, whole, keep: np.ndarray, x: np.ndarray, xw: np.ndarray, data: Table,
                    J: np.ndarray | None) -> np.ndarray:
    """The flat Jacobian of `whole` at xw (x widened): `small`'s columns (J, its flat Jacobian at x, if the
    caller has it) and, where `small` offers ``held_columns``, the dropped terms' from it — the same numbers
    as `whole`'s own Jacobian, without walking `whole`'s longer chains."""
    held = getattr(type(small), "held_columns", None)
    if held is None:
        return _flat_jac(whole, xw, data)
    Js = _flat_jac(small, x, data) if J is None else J
    out = np.zeros((Js.shape[0], xw.size))
    out[:, keep] = Js
    gone = np.setdiff1d(np.arange(xw.size), keep)
    names = whole.parameter_names()
    H = held(small, x, data, [names[i] for i in gone])
    out[:, gone] = H.reshape(Js.shape[0], -1)
    return out


def weakly_freed(model: MeasurementModel, data: Table, x: np.ndarray, before: np.ndarray,
                 after: np.ndarray, J: np.ndarray | None = None, prior: np.ndarray | None = None) -> np.ndarray:
    """Mask of the parameters free in `after` but not in `before` whose 1σ at x (σ̂²(JᵀJ)⁻¹ over
    `after`'s free set, σ̂ the residuals' robust scale at x) is no smaller than their prior 1σ
    (`prior`, (P,) SI; default `pipeline.accuracy.prior`'s): the data do not determine them."""
    new = after & ~before
    if not new.any():
        return new
    if prior is None:
        from pipeline.accuracy.prior import prior_sigma

        prior = prior_sigma(model)[0]

    r = model.residuals(x, data).ravel()
    Jf = (_flat_jac(model, x, data) if J is None else J)[:, after]  # J: the flat Jacobian at x, if the caller has it
    if r.size <= Jf.shape[1]:  # no residual degrees of freedom: no noise level to judge by
        return np.zeros_like(new)
    # the noise level by the residuals' median absolute value (Gaussian-consistent), so that gross
    # errors a robust loss is riding out do not make every newly freed parameter look undetermined
    scale = float(np.median(np.abs(r))) * 1.4826 or float(np.mean(np.abs(r))) * 1.2533  # MAD; mean |r| if MAD = 0
    sigma = scale * np.sqrt(r.size / max(r.size - Jf.shape[1], 1))
    std = np.zeros(x.size)
    std[after] = np.sqrt(np.clip(np.diag(covariance(Jf, sigma)), 0, None))
    return new & (std >= prior)


def _solve(model: MeasurementModel, data: Table, x_start: np.ndarray, free: np.ndarray,
           options: FitOptions, history: list[float]):
    """One least-squares solve over the free parameters, the others held at x_start."""

    def expand(z: np.ndarray) -> np.ndarray:
        x = x_start.copy()
        x[free] = z
        return x

    def fun(z: np.ndarray) -> np.ndarray:
        r = model.residuals(expand(z), data).ravel()
        history.append(float(np.sqrt(np.mean(r**2))))
        return r

    columns = getattr(type(model), "jacobian_columns", None)  # the model's own (not a wrapper's passed on)

    def jac(z: np.ndarray) -> np.ndarray:
        if columns is not None:  # only the free columns: the same numbers, the fixed ones not computed
            J = columns(model, expand(z), data, free)
            return J.reshape(-1, J.shape[-1])
        return _flat_jac(model, expand(z), data)[:, free]

    m = n_rows(data) * model.residual_dim
    method = "lm" if options.loss == "linear" and m >= free.sum() else "trf"
    return least_squares(fun, x_start[free], jac=jac, method=method, x_scale="jac", loss=options.loss,
                         f_scale=options.f_scale, max_nfev=options.max_nfev, xtol=1e-12, ftol=1e-12, gtol=1e-12)


def covariance(J: np.ndarray, sigma: float) -> np.ndarray:
    """σ²·(JᵀJ)⁻¹ via the SVD (stable when JᵀJ is ill-conditioned)."""
    _, s, Vt = np.linalg.svd(J, full_matrices=False)
    s_inv2 = np.where(s > s[0] * 1e-12, 1.0 / s**2, 0.0) if s.size else s
    return sigma**2 * (Vt.T * s_inv2) @ Vt


def point_accuracy(model: MeasurementModel, f: Fit, data: Table) -> np.ndarray:
    """Predicted 3-D 1σ error of the model's points at each measurement, (n,) m:
    sqrt(trace(Jp Σ Jpᵀ)) with Σ the covariance of the free parameters."""
    _, Jp = model.points(f.x, data)
    Jp = Jp[:, :, f.free]
    return np.sqrt(np.einsum("nip,pq,niq->n", Jp, f.cov, Jp))


def holdout_warning(n: int, k: int, residual_dim: int, n_free: int) -> str | None:
    """A warning when k-fold training sets are too small for the held-out figure to mean much:
    each training fold must hold clearly more residuals than identifiable parameters."""
    n_train = n - -(-n // k)  # n minus the largest fold
    if n_train * residual_dim < 1.5 * n_free:
        return (f"held-out RMS is unreliable: each {k}-fold training set has {n_train} measurements "
                f"({n_train * residual_dim} residuals) for {n_free} identifiable parameters; record more measurements")
    return None


@single_threaded
def cross_validate(model: MeasurementModel, data: Table, k: int = 5, seed: int = 0,
                   options: FitOptions = FitOptions(), groups: np.ndarray | None = None) -> np.ndarray:
    """Held-out residuals (n, residual_dim) m: each fold predicted by a fit on the others; the folds
    keep every face, placement and joint range of the design in every training set (`folds.design_folds`) and,
    without `groups`, the rows the model keeps together (`natural_groups.holdout_groups`: a camera's images)."""
    from pipeline.identify.folds import design_folds
    from pipeline.identify.natural_groups import holdout_groups

    n = n_rows(data)
    groups = holdout_groups(model, data) if groups is None else groups
    out = np.full((n, model.residual_dim), np.nan)
    for test in design_folds(n, k, seed, groups, data):
        train = np.setdiff1d(np.arange(n), test)
        f = fit(model, take(data, train), replace(options, before=False))  # only its parameters are used
        out[test] = model.residuals(f.x, take(data, test))
    return out
