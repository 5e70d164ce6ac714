"""Honest uncertainty for camera calibrations: the corners of one image are not independent.

A robot's pose error at an image moves all of that image's corners together, so residuals are
correlated within an image and σ̂²(JᵀJ)⁻¹ (independent corners) is far too optimistic.  The
error model here is the random-effects model of `pipeline.diagnose.clustered`: per image g,
``r_g = Z_g u_g + e_g`` with u_g the image's rigid pose error (6 components, covariance Ψ) and
e_g the detector's noise (σ_w² I); Z_g = d residual / d (board ↔ camera pose), the columns of
the chain's base frame.  Ψ and σ_w are estimated from the residuals (moments).

`clustered_fit` then refits by generalised least squares (residuals and Jacobian whitened by
Σ^{-1/2}, which also weighs images by how much they say) and states the covariance of that
fit, (J_wᵀ J_w)⁻¹ σ_w².
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pipeline.identify.least_squares import Fit, FitOptions, covariance, fit
from pipeline.identify.model import Table


def image_whitener(model, x: np.ndarray, data: Table, n_fitted: int):
    """The random-effects whitener (module docstring) at x, or None when it cannot be estimated."""
    from pipeline.diagnose.clustered import cluster_whitener

    r = model.residuals(x, data).ravel()
    J = model.jacobian(x, data).reshape(r.size, -1)
    ib = model.parameter_names().index("base.x")
    cluster = np.repeat(np.asarray(data["image"]), model.residual_dim)
    return cluster_whitener(r, J[:, ib:ib + 6], cluster, n_fitted=n_fitted)


@dataclass(frozen=True)
class Whitened:
    """A measurement model whose residuals and Jacobian are whitened by W (for `fit`)."""

    model: object
    W: object

    def __getattr__(self, name):
        return getattr(self.model, name)

    @property
    def residual_dim(self) -> int:
        return self.model.residual_dim

    def residuals(self, x: np.ndarray, data: Table) -> np.ndarray:
        r = self.model.residuals(x, data)
        return self.W(r.reshape(-1, 1)).reshape(r.shape) / self.W.sigma_within

    def jacobian(self, x: np.ndarray, data: Table) -> np.ndarray:
        J = self.model.jacobian(x, data)
        return self.W(J.reshape(-1, J.shape[-1])).reshape(J.shape) / self.W.sigma_within


def clustered_fit(model, data: Table, options: FitOptions = FitOptions(before=False)) -> tuple[Fit, object]:
    """An ordinary fit, then the image random-effects model estimated at it and a GLS refit.
    Returns the GLS fit (x, std, cov from the whitened problem: σ in px of the detector noise
    scale) and the whitener (None: the ordinary fit, its σ̂²(JᵀJ)⁻¹ — too few corners per image)."""
    f0 = fit(model, data, options)
    W = image_whitener(model, f0.x, data, int(f0.free.sum()))
    if W is None:
        return f0, None
    wm = Whitened(model, W)
    fixed = tuple(n for n, fr in zip(f0.names, f0.free) if not fr)
    f1 = fit(wm, data, replace(options, x0=f0.x, fixed=fixed, before=False))
    Jf = wm.jacobian(f1.x, data).reshape(-1, f1.x.size)[:, f1.free]
    cov = covariance(Jf, 1.0)  # whitened rows have unit variance
    std = np.zeros_like(f1.x)
    std[f1.free] = np.sqrt(np.clip(np.diag(cov), 0, None))
    f1.cov, f1.std = cov, std
    f1.residuals_after = model.residuals(f1.x, data)
    f1.sigma = W.sigma_within
    return f1, W
