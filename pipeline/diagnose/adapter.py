"""What is system-specific in a diagnosis (`Adapter`), and the lack-of-fit test under an adapter's
physical cluster-error model (`physical_lack_of_fit`, the scanner's pose errors)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.stats

from pipeline.diagnose import lack_of_fit
from pipeline.diagnose.effects import Effect
from pipeline.diagnose.select import PhysicalModel, Whitener, physical_components, physical_whitener


@dataclass(frozen=True)
class Adapter:
    """What is system-specific in a diagnosis (everything else is shared).

    - `library`: the candidate effects;
    - `signatures(x, data, effects)`: list of (n, residual_dim, k_e) residual change per unit
      parameter of each effect at geometric parameters x (m/unit);
    - `variables(x)`: lack-of-fit `Variable`s whose rows are the flattened residual rows
      (measurement-major, n·residual_dim);
    - `time_s` (n,): time since start (s), for cross-validation blocks;
    - `located(effect)`: (label, values (n,)) — the variable an effect acts through, for the
      added-variable plots (None: the measurement index);
    - `cluster` (n,): the cluster (pose) of each measurement when several measurements share
      one pose's error (None: every measurement is its own cluster), and `cluster_basis(x)`
      (n, residual_dim, p): how a pose's error reaches each residual (None: a shift per
      residual axis) — the tests are then made under the random-effects model of
      `select.cluster_whitener` (pose-clustered inference, docs/guide/diagnose.md);
    - `cluster_model(x)`: (B (n, residual_dim, p), column groups) — a physical model of the cluster
      error (B_g e_g, e_g ~ N(0, diag θ), θ shared within each group, estimated from the data):
      the lack-of-fit test then whitens by it and takes its p-values from a parametric bootstrap
      under it (`physical_reference`) instead of the sign flips;
    - `shared_error`: (Z (n·residual_dim, g) group membership, τ² m²) — an error shared by the
      rows of a group with a variance known a priori (a jig face's machining error within the
      jig's tolerance); the refit's parameter std then use `confirm.shared_error_covariance`.
    """

    library: list[Effect]
    signatures: Callable[[np.ndarray, object, tuple], list[np.ndarray]]
    variables: Callable[[np.ndarray], list]
    time_s: np.ndarray
    located: Callable[[Effect], tuple[str, np.ndarray] | None] = lambda e: None
    cluster: np.ndarray | None = None
    cluster_basis: Callable[[np.ndarray], np.ndarray] | None = None
    noise_shape: Callable[[np.ndarray], np.ndarray] | None = None
    cluster_model: Callable[[np.ndarray], tuple[np.ndarray, list[np.ndarray]]] | None = None
    shared_error: tuple[np.ndarray, float] | None = None
    held: tuple[str, ...] = ()  # weak-gauge parameters the geometric baseline holds at the model's nominal
    # refit(effects): the joint refit's exact model of those effects when some are not additive
    # enough (`confirm.AugmentedModel.exact`), or None (the additive model)
    refit: Callable[[tuple], Callable | None] | None = None
    # floor_variance(x) (n·residual_dim,) m²: the noise floor the campaign supports (`verdict.floor_check`)
    floor_variance: Callable[[np.ndarray], np.ndarray] | None = None


N_DRAWS = 2999  # parametric bootstrap draws of the lack-of-fit reference


def physical_reference(model_of_x: tuple, r: np.ndarray, A: np.ndarray, src: list, nm, cl: np.ndarray,
                       M, W: Whitener, seed: int) -> tuple[Whitener, np.ndarray]:
    """(whitener, whitened null draws (nk, N_DRAWS)) of the adapter's physical cluster-error model
    (`model_of_x` = `Adapter.cluster_model(x)`: (B, column groups)) for residual r of design A: the error's variances θ by REML on the
    measurement-whitened problem (`select.physical_components`, within σ_w from W), each cluster
    whitened by its own covariance (`select.physical_whitener`), and residuals drawn from the
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


def physical_lack_of_fit(ad: Adapter, x: np.ndarray, r: np.ndarray, A: np.ndarray, variables: list, src: list, nm,
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
