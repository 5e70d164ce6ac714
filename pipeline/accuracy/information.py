"""How much a campaign teaches: information, not row counts (functional core).

A row that repeats another (same configuration, same measured direction) adds no
information: it cannot fix a parameter the first did not, and its residual cannot tell the
model's error from the instrument's.  So the thin-data verdict counts

* distinct measurements: per-measurement Jacobian blocks that differ (to a relative 1e-9);
* the identified parameters p and what a full model identifies, p_full: the rank (pivoted QR of
  the unit-column Jacobian, as identify's rank test) of the point Jacobian over the map's
  configurations, i.e. what a campaign that measured the whole point everywhere would fix;
* the residual degrees of freedom left after the identification, from distinct residuals only:
  dof = distinct measurements × residual_dim − p.  Below MIN_DOF the residual σ̂ (hence the
  fitted parameters' covariance) is not determined by the data; at or below 0 it is zero by
  construction (the fit interpolates);
* the condition number of the column-scaled identification Jacobian.

All Jacobians in SI (m per parameter unit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import chdtri

from pipeline.identify.identifiability import analyse

MIN_DOF = 10  # distinct residuals beyond the identified parameters for σ̂ to mean something (±22 % at 1σ)
COMFORT_PER_PARAMETER = 3  # distinct residuals per parameter of the full model a campaign should aim for


@dataclass(frozen=True)
class Information:
    """What the campaign's data determine (see module docstring)."""

    n_measurements: int
    n_distinct: int
    residuals_distinct: int
    p: int  # identified (free) parameters
    p_full: int  # parameters a campaign measuring the whole point over the map identifies
    n_parameters: int
    condition: float  # of the column-scaled Jacobian over the free parameters (inf if rank-deficient)

    @property
    def dof(self) -> int:
        return self.residuals_distinct - self.p

    def to_dict(self) -> dict:
        return {"n_measurements": self.n_measurements, "n_distinct": self.n_distinct,
                "residuals_distinct": self.residuals_distinct, "identified": self.p,
                "identified_full_model": self.p_full, "parameters": self.n_parameters, "dof": self.dof,
                "min_dof": MIN_DOF, "condition_number": self.condition}


def distinct_rows(Jm: np.ndarray, residual_dim: int, rtol: float = 1e-9) -> int:
    """Number of measurements whose Jacobian blocks differ (Jm (n·k, P) flat, k = residual_dim)."""
    n = Jm.shape[0] // max(residual_dim, 1)
    if n == 0:
        return 0
    B = Jm.reshape(n, -1)
    scale = np.max(np.abs(B), axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    q = np.round(B / scale / rtol).astype(np.int64)
    return int(np.unique(q, axis=0).shape[0])


def scaled_condition(J: np.ndarray) -> float:
    """Condition number of J with unit-norm columns (inf when a column is zero or J is rank-deficient)."""
    if J.size == 0 or J.shape[1] == 0:
        return 1.0
    norms = np.linalg.norm(J, axis=0)
    if np.any(norms == 0):
        return math.inf
    s = np.linalg.svd(J / norms, compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 and J.shape[0] >= J.shape[1] else math.inf


def full_rank(Jp_map: np.ndarray, names: list[str]) -> int:
    """Parameters a campaign measuring the whole 3-D point at the map's configurations identifies."""
    J = Jp_map.reshape(-1, Jp_map.shape[-1])
    return int(analyse(J, names).free.sum()) if J.shape[0] else 0


def information(Jm: np.ndarray, free: np.ndarray, residual_dim: int, Jp_map: np.ndarray, names: list[str]) -> Information:
    free = np.asarray(free, bool)
    n = Jm.shape[0] // max(residual_dim, 1)
    d = distinct_rows(Jm, residual_dim)
    return Information(n_measurements=n, n_distinct=d, residuals_distinct=d * residual_dim, p=int(free.sum()),
                       p_full=max(full_rank(Jp_map, names), int(free.sum())), n_parameters=free.size,
                       condition=scaled_condition(Jm[:, free]))


def fit_inflation(dof: int, confidence: float = 0.95) -> float:
    """Factor on the fitted parameters' covariance for a σ̂ from few degrees of freedom: the
    `confidence` upper bound of σ²/σ̂² (dof/χ²_dof quantile); inf with no degree of freedom, 1 from
    MIN_DOF on (the 95 % bound then carries the usual spread)."""
    if dof <= 0:
        return math.inf
    if dof >= MIN_DOF:
        return 1.0
    return float(dof / chdtri(dof, confidence))


def more_needed(info: Information, residual_dim: int) -> int:
    """Distinct measurements to add so that the full model has COMFORT_PER_PARAMETER distinct
    residuals per parameter (and at least MIN_DOF beyond its parameters)."""
    want = max(COMFORT_PER_PARAMETER * info.p_full, info.p_full + MIN_DOF)
    return max(0, math.ceil((want - info.residuals_distinct) / max(residual_dim, 1)))
