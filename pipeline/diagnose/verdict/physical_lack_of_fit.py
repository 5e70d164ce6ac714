"""Lack of fit under an adapter's physical cluster-error model (the scanner's pose errors):
the parametric-bootstrap reference (`physical_reference`) and the stepwise test of every
lack-of-fit variable against it (`physical_lack_of_fit`).  Residuals in m, flattened
measurement-major (n·residual_dim rows)."""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.stats

from pipeline.diagnose.inference.clustered import (
    PhysicalModel,
    Whitener,
    physical_components,
    physical_whitener,
)
from pipeline.diagnose.verdict import lack_of_fit

N_DRAWS = 2999  # parametric bootstrap draws of the lack-of-fit reference


def physical_reference(model_of_x: tuple, r: np.ndarray, A: np.ndarray, src: list, nm, cl: np.ndarray,
                       M, W: Whitener, seed: int) -> tuple[Whitener, np.ndarray]:
    """(whitener, whitened null draws (nk, N_DRAWS)) of the adapter's physical cluster-error model
    (`model_of_x` = `Adapter.cluster_model(x)`: (B, column groups)) for residual r of design A: the error's variances θ by REML on the
    measurement-whitened problem (`clustered.physical_components`, within σ_w from W), each cluster
    whitened by its own covariance (`clustered.physical_whitener`), and residuals drawn from the
    fitted model (measurement noise `nm` + B_g e_g) through the same whitener."""
    Bm, groups = model_of_x
    Bm = np.asarray(Bm, float).reshape(r.size, -1)
    s2 = W.sigma_within**2
    theta, info = physical_components(r, A, Bm, groups, cl, s2, pre=M, information=True)
    # the variances are estimated (20 poses: ~20 % error): each draw scales them by χ²_ν/ν, ν = 2 I_λ
    # from the REML information of their common scale λ (θ = λθ̂), so the reference carries that error
    i_scale = float(theta @ info @ theta)
    pm = PhysicalModel(src, nm.variances, Bm, groups, theta, cl, scale_dof=2 * i_scale if i_scale > 0 else np.inf)
    Wp = physical_whitener(pm, s2, M, W.n_effective)
    return Wp, Wp(pm.draw(N_DRAWS, seed))


def _extremeness(t) -> tuple[float, float]:
    """Order of lack-of-fit results, most extreme first: p-value, then the nominal F tail of the
    statistic (bootstrap p-values tie at their floor)."""
    return t.p_value, float(scipy.stats.f.sf(t.statistic, *t.dof)) if t.dof[0] else 1.0


def physical_lack_of_fit(ad, x: np.ndarray, r: np.ndarray, A: np.ndarray, variables: list, src: list, nm,
                         cl: np.ndarray, M, W: Whitener, alpha: float, seed: int) -> list:
    """Lack of fit under the adapter's physical cluster-error model (`physical_reference`), stepwise:
    test every variable (scan statistic, parametric bootstrap, Holm); when several are significant
    the most extreme one (smallest p, then smallest nominal F tail of its best scan element) is
    taken, its located bump (`lack_of_fit.located_columns`) joins the design, the model is refitted
    and the others are tested again given it (Holm over those left; p never below the step
    before).  Structure in one variable (a bump in J2's transmission) also shows, before it is
    accounted for, in every variable whose scan can partly imitate it; given it, those are no
    longer significant.  Returns one `LackOfFit` per variable, in order."""
    by_name = {v.name: v for v in variables}
    done: dict = {}
    rest, D, floor = list(variables), A, 0.0
    model_of_x = ad.cluster_model(x)  # the same x at every step
    while rest:
        rr = r - D @ np.linalg.lstsq(D, r, rcond=None)[0]
        Wl, draws = physical_reference(model_of_x, rr, D, src, nm, cl, M, W, seed)
        vw = [dataclasses.replace(v, columns=Wl(v.columns)) for v in rest]
        lof = lack_of_fit.test(Wl(rr), Wl(D), vw, Wl.n_effective - D.shape[1], alpha, whiten=Wl,
                               original=(rr, D, rest), cluster=cl, seed=seed, draws=draws)
        lof = [dataclasses.replace(t, p_holm=max(t.p_holm, floor)) for t in lof]
        sig = [t for t in lof if t.significant]
        if len(sig) <= 1:
            done.update({t.variable: t for t in lof})
            break
        best = min(sig, key=_extremeness)
        done[best.variable] = best
        floor = best.p_holm
        D = np.hstack([D, lack_of_fit.located_columns(by_name[best.variable], best.region)])
        rest = [v for v in rest if v.name != best.variable]
    return [done[v.name] for v in variables]
