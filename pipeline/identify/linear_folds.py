"""k-fold held-out residuals on the problem linearised at a solved point, in closed form.

For the linear model r + J·δ (J (m, p) the Jacobian of the free parameters at a point, r (m,) the residuals
there, rows measurement-major), the full fit leaves e = (I − H)·r, H = J(JᵀJ)⁻¹Jᵀ, and the fit without the rows
T of a fold predicts them with the residuals e'_T = (I − H_TT)⁻¹·e_T — exact for a model linear in its
parameters, one factorisation (an orthonormal basis of J's columns) for every fold.  At a least-squares solution
of a nonlinear model this is the k-fold cross-validation to first order in each fold's parameter move (a few
µm on a whole humanoid's millimetre held-out errors, against a refit per fold); at another point (the solution
of a model with fewer free parameters) it scores the model linearised there: one Gauss–Newton step per fold.
`scaled_basis` is that basis; `free_at` the rank test of a candidate's free set on the point's Jacobian.
"""

from __future__ import annotations

import numpy as np

from pipeline.identify.identifiability import analyse


def scaled_basis(J: np.ndarray, rel_tol: float = 1e-10, base: np.ndarray | None = None) -> np.ndarray:
    """Orthonormal basis (m, rank) of J's columns, each scaled to unit norm first (units do not matter);
    directions below `rel_tol` of the largest left out.  With `base` (m, b), an orthonormal basis of some of
    J's columns already: those columns' share is `base`, and only what of the others it does not span is added
    (a candidate's basis from the model it extends, at the price of its own columns)."""
    J = np.asarray(J, float)
    norms = np.linalg.norm(J, axis=0)
    keep = norms > 0
    if not keep.any():
        return np.zeros((J.shape[0], 0)) if base is None else base
    Js = J[:, keep] / norms[keep]
    if base is not None:
        Js = Js - base @ (base.T @ Js)
        nr = np.linalg.norm(Js, axis=0)
        Js = Js[:, nr > rel_tol ** 0.5]  # columns base spans (its own) drop out here
        if Js.shape[1] == 0:
            return base
        Js = Js - base @ (base.T @ Js)  # twice is enough (Gram–Schmidt re-orthogonalised)
    Q, R = np.linalg.qr(Js)
    d = np.abs(np.diag(R))
    if d.min() <= rel_tol ** 0.5 * d.max():  # nearly dependent columns: the rank from the singular values
        U, sv, _ = np.linalg.svd(Js, full_matrices=False)
        Q = U[:, sv > rel_tol * sv[0]]
    return Q if base is None else np.hstack([base, Q])


def kfold_linear(J: np.ndarray | None, r: np.ndarray, folds: list[np.ndarray], kd: int,
                 U: np.ndarray | None = None) -> np.ndarray:
    """Held-out residuals (n, kd) of the linearised model (module docstring); `folds` hold measurement indices
    (each measurement's kd rows go together); measurements in no fold are NaN.  `U`: the orthonormal basis of
    J's columns when known (`scaled_basis`), J then unused.  Each fold by the push-through identity
    (I − UₜUₜᵀ)⁻¹e = e + Uₜ(I − UₜᵀUₜ)⁻¹Uₜᵀe: a rank × rank solve."""
    U = scaled_basis(np.asarray(J, float)) if U is None else U
    r = np.asarray(r, float).ravel()
    e = r - U @ (U.T @ r)
    out = np.full((r.size // kd, kd), np.nan)
    eye = np.eye(U.shape[1])
    for test in folds:
        rows = (np.asarray(test, int)[:, None] * kd + np.arange(kd)).ravel()
        Ut, et = U[rows], e[rows]
        try:
            h = et + Ut @ np.linalg.solve(eye - Ut.T @ Ut, Ut.T @ et)
            if not np.all(np.isfinite(h)):
                raise np.linalg.LinAlgError
        except np.linalg.LinAlgError:  # the fold alone carries a direction: the least-squares answer
            h = np.linalg.lstsq(np.eye(rows.size) - Ut @ Ut.T, et, rcond=None)[0]
        out[test] = h.reshape(len(test), kd)
    return out


def kfold_at(model, data, k: int, seed: int, options=None, groups: np.ndarray | None = None, *,
             solution) -> np.ndarray:
    """Held-out residuals (n, residual_dim) m of `solution` (a `Fit` of `model` on `data`) by k-fold
    cross-validation in closed form (module docstring): the folds of `least_squares.cross_validate`, each
    predicted by the model linearised at the solution with its free set, instead of a refit per fold.
    `options` is accepted for the same call as `cross_validate` (the solution already holds its effect)."""
    from pipeline.identify.folds import design_folds

    r = np.asarray(model.residuals(solution.x, data), float)
    n, kd = r.shape
    J = np.asarray(model.jacobian(solution.x, data), float).reshape(n * kd, -1)[:, np.asarray(solution.free, bool)]
    return kfold_linear(J, r.ravel(), design_folds(n, k, seed, groups, data), kd)


def free_at(J: np.ndarray, names: list[str], fixed: np.ndarray, priority: np.ndarray | None) -> np.ndarray:
    """The free set (P,) bool the rank test gives at a point whose flat Jacobian is J (m, P), `fixed` held."""
    return analyse(J, names, fixed, priority).free


CLOSED_FORM_PARAMETERS = 120  # a model this wide (a whole robot's tree) has its model choice scored in closed form
SOLVES = 3  # candidates solved per round of a selection at most (the best linearised, then any still better)


class Linearised:
    """Scores of candidate models (lists of parameter groups) by k-fold held-out error on the problem linearised
    at a solved model: a candidate not solved is scored at the solution of the model it extends (its free set by
    the rank test there, `free_at`), a solved one at its own solution.  `options_for(groups)` gives a candidate's
    `FitOptions` (its fixed parameters); `solve` fits one (warm from a given start) and keeps its point."""

    def __init__(self, model, data, folds: list[np.ndarray], options_for):
        from pipeline.identify.identifiability import triangular_factor

        self.model, self.data, self.folds, self.options_for = model, data, folds, options_for
        self.names = list(model.parameter_names())
        self.priority = getattr(model, "priority", lambda: None)()
        self.solved: dict[tuple, tuple] = {}  # groups → (x, flat J (m, P), r (m,), free (P,), R (P, P) of J)
        self._factor = triangular_factor
        self._basis: dict[tuple, tuple] = {}  # solved groups → (free set by the rank test, basis of those columns)

    def solve(self, groups: list[str], x0: np.ndarray | None = None) -> np.ndarray:
        """Fit the candidate (from `x0`, else the model's start) and keep its point; its x."""
        from dataclasses import replace

        from pipeline.identify.least_squares import fit

        f = fit(self.model, self.data, replace(self.options_for(groups), before=False, x0=x0))
        r = np.asarray(f.residuals_after, float).ravel()
        J = np.asarray(self.model.jacobian(f.x, self.data), float).reshape(r.size, -1)
        self.solved[tuple(groups)] = (f.x, J, r, np.asarray(f.free, bool), self._factor(J))
        return f.x

    def errors(self, groups: list[str], base: list[str]) -> np.ndarray:
        """Squared held-out error per measurement (n,) of the candidate: at its own solution when solved, else
        linearised at the solved `base`'s."""
        own = self.solved.get(tuple(groups))
        kd = self.model.residual_dim
        if own is not None:
            _, J, r, free, _ = own
            return np.nansum(kfold_linear(J[:, free], r, self.folds, kd) ** 2, axis=1)
        _, J, r, _, R = self.solved[tuple(base)]
        fixed = np.array([n in set(self.options_for(groups).fixed) for n in self.names])
        free = free_at(R, self.names, fixed, self.priority)
        if tuple(base) not in self._basis:  # the base's free set by the same rank test at this point, its basis
            fb = free_at(R, self.names, np.array([n in set(self.options_for(base).fixed) for n in self.names]),
                         self.priority)
            self._basis[tuple(base)] = (fb, scaled_basis(J[:, fb]))
        free_b, U_b = self._basis[tuple(base)]
        # a candidate that extends the base's free set: the base's basis and its own columns
        U = scaled_basis(J[:, free & ~free_b], base=U_b) if free[free_b].all() else None
        h = kfold_linear(J[:, free], r, self.folds, kd, U=U)
        return np.nansum(h**2, axis=1)

    def settle(self, trial: dict, kept: list[str], rms) -> tuple[str, set]:
        """The candidate of `trial` ({candidate: errors}, scored linearised at the solution of `kept`) a round
        chooses: the best is solved (warm from `kept`'s solution) and rescored at its own solution; while an
        unsolved candidate then scores better, it is solved in turn (at most `SOLVES`); the best solved wins.
        Returns (it, the candidates solved); `trial` is updated with their exact scores."""
        x_base = self.solved[tuple(kept)][0]
        done: set = set()
        for _ in range(SOLVES):
            c = min(trial, key=lambda c: rms(trial[c]))
            if c in done:
                break
            self.solve(kept + [c], x_base)
            trial[c] = self.errors(kept + [c], kept)
            done.add(c)
        return min(done, key=lambda c: rms(trial[c])), done
