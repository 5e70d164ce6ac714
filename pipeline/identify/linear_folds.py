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


def scaled_basis(J: np.ndarray, rel_tol: float = 1e-10) -> np.ndarray:
    """Orthonormal basis (m, rank) of J's columns, each scaled to unit norm first (units do not matter);
    directions below `rel_tol` of the largest singular value are left out."""
    norms = np.linalg.norm(J, axis=0)
    keep = norms > 0
    if not keep.any():
        return np.zeros((J.shape[0], 0))
    U, s, _ = np.linalg.svd(J[:, keep] / norms[keep], full_matrices=False)
    return U[:, s > rel_tol * s[0]]


def kfold_linear(J: np.ndarray, r: np.ndarray, folds: list[np.ndarray], kd: int) -> np.ndarray:
    """Held-out residuals (n, kd) of the linearised model (module docstring); `folds` hold measurement indices
    (each measurement's kd rows go together); measurements in no fold are NaN."""
    U = scaled_basis(np.asarray(J, float))
    r = np.asarray(r, float).ravel()
    e = r - U @ (U.T @ r)
    out = np.full((r.size // kd, kd), np.nan)
    for test in folds:
        rows = (np.asarray(test, int)[:, None] * kd + np.arange(kd)).ravel()
        Ut = U[rows]
        out[test] = np.linalg.lstsq(np.eye(rows.size) - Ut @ Ut.T, e[rows], rcond=None)[0].reshape(len(test), kd)
    return out


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
        if own is not None:
            _, J, r, free, _ = own
        else:
            _, J, r, _, R = self.solved[tuple(base)]
            fixed = np.array([n in set(self.options_for(groups).fixed) for n in self.names])
            free = free_at(R, self.names, fixed, self.priority)
        h = kfold_linear(J[:, free], r, self.folds, self.model.residual_dim)
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
