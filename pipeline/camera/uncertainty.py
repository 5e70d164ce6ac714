"""Honest uncertainty for camera calibrations: the corners of one image are not independent.

A robot's pose error at an image moves all of that image's corners together, so residuals are
correlated within an image and σ̂²(JᵀJ)⁻¹ (independent corners) is far too optimistic.  The
error model here is the random-effects model of `pipeline.diagnose.inference.clustered`: per image g,
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
    from pipeline.diagnose.inference.clustered import cluster_whitener

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


def refit(model, data: Table, x0: np.ndarray, free: np.ndarray) -> np.ndarray:
    """A warm-started least-squares solve of the free parameters from x0 (no rank analysis:
    the free set is the full fit's); the resampled fits of `image_jackknife`."""
    from scipy.optimize import least_squares

    def expand(z):
        x = x0.copy()
        x[free] = z
        return x

    sol = least_squares(lambda z: model.residuals(expand(z), data).ravel(), x0[free],
                        jac=lambda z: model.jacobian(expand(z), data).reshape(-1, x0.size)[:, free],
                        method="lm", x_scale="jac", xtol=1e-10, ftol=1e-10)
    return expand(sol.x)


def image_jackknife(model, data: Table, x: np.ndarray, free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Delete-one-image jackknife of a fit at x over its free parameters: (σ (P,), estimates
    (G,P)).  σ² = (G−1)/G Σ_g (x₍₋g₎ − x̄)²: honest for correlated corners within an image
    and for any per-image error the model does not describe; G refits from x."""
    from pipeline.identify.model import take

    img = np.asarray(data["image"])
    est = np.array([refit(model, take(data, img != g), x, free) for g in np.unique(img)])
    G = len(est)
    return np.sqrt((G - 1) / G * np.sum((est - est.mean(0)) ** 2, axis=0)), est


def clustered_fit(model, data: Table, options: FitOptions = FitOptions(before=False)) -> tuple[Fit, object, Fit]:
    """An ordinary fit, then the image random-effects model estimated at it and a GLS refit (warm
    started, same free set).  Returns the GLS fit (x; std and cov from the whitened problem), the
    whitener (None: too few corners per image — the GLS fit is then the ordinary one) and the
    ordinary fit."""
    f0 = fit(model, data, options)
    W = image_whitener(model, f0.x, data, int(f0.free.sum()))
    if W is None:
        return f0, None, f0
    wm = Whitened(model, W)
    x = refit(wm, data, f0.x, f0.free)
    Jf = wm.jacobian(x, data).reshape(-1, x.size)[:, f0.free]
    cov = covariance(Jf, 1.0)  # whitened rows have unit variance
    std = np.zeros_like(x)
    std[f0.free] = np.sqrt(np.clip(np.diag(cov), 0, None))
    f1 = replace(f0, x=x, cov=cov, std=std, residuals_after=model.residuals(x, data), sigma=W.sigma_within)
    return f1, W, f0
