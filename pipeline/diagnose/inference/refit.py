"""Steps 4–5 of the diagnosis: the joint refit of geometry + accepted effects (parameters with
honest 1σ) and the evidence of each finding (ablation cross-validation, ΔBIC, bootstrap).

- `joint_refit`: nonlinear least squares of the augmented model (`augmented.AugmentedModel`); with
  pose clusters, cluster-robust (CR2) standard errors; with errors shared within groups (a jig
  face), the sandwich covariance; t degrees of freedom per parameter;
- `finding_records`: one finding dict per accepted effect (parameters with `ci95`, the selection's
  grouped F and Holm p, ablation CV, ΔBIC, bootstrap frequency — of any of its forms — look-alikes), with its fitted
  contribution (n, k) and its columns of the final design.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.diagnose.inference import augmented, resampling
from pipeline.diagnose.inference.clustered import measurement_covariance
from pipeline.diagnose.inference.projection import orthonormal, project_out
from pipeline.identify.least_squares import Fit, FitOptions, fit


def _dof(v: float) -> float | None:
    """A dof for JSON: None when infinite (a known variance: normal quantiles)."""
    return float(v) if np.isfinite(v) else None


@dataclass(frozen=True)
class Refit:
    """The final model: parameters z (geometry then effects, physical units), residual r_final (nk,),
    design A (nk, free columns, per fitted unit), 1σ std and t dof per parameter, σ, free mask."""

    z: np.ndarray
    r_final: np.ndarray
    A: np.ndarray
    std: np.ndarray
    par_dof: np.ndarray
    sigma_after: float
    free_a: np.ndarray
    S: np.ndarray | None = None  # (n, k, Σk_e) the effects' columns the refit held (m per unit), None: at z


def joint_refit(model, table, f: Fit, ad, adapter, lib: list, accepted: list[int], Jf: np.ndarray,
                r: np.ndarray, dof: int, cl: np.ndarray | None, nm, src: list | None,
                S: list[np.ndarray] | None = None) -> Refit:
    """Step 4 (module docstring).  `f` the geometry fit, `ad` the adapter (`adapter` the caller's, or
    None for the touch default), `cl` per-row cluster ids, `nm`/`src` the noise model and its sources;
    `S` every library effect's signature at the geometric solution (nk, k_e), held by the refit where the
    adapter asks for it (`Adapter.frozen_refit`)."""
    nk = r.size
    x, free, names = f.x, f.free, f.names
    if not accepted:
        return Refit(x, r, Jf, f.std, np.full(x.size, float(max(dof, 1))), f.sigma, free)
    acc_eff = tuple(lib[i] for i in accepted)
    n = f.residuals_after.shape[0]
    frozen = (np.concatenate([S[i].reshape(n, -1, lib[i].k) for i in accepted], axis=2)
              if S is not None and ad.frozen_refit and ad.refit is None else None)
    aug = augmented.AugmentedModel(model, acc_eff, None if adapter is None else ad.signatures, scaled=True,
                                   exact=None if ad.refit is None else ad.refit(acc_eff), frozen=frozen)
    z0 = np.concatenate([x, np.zeros(sum(lib[i].k for i in accepted))])
    # what the geometry fit held stays held: the design the selection tested against is the geometry fit's free
    # columns + the effects.  Adding effects cannot make a held direction identifiable; freed by the refit's own
    # rank test on the edge, it costs the held-out check its like-for-like baseline (a 4 000-conditioned direction
    # that predicts a left-out touch 0.4 mm off), and an exact lens term (`Adapter.refit`) lifting a weak gauge's
    # exact degeneracy slightly would let that gauge absorb part of the lens effect
    held = tuple(name for name, b in zip(names, free) if not b)
    fa = fit(aug, table, FitOptions(x0=z0, fixed=held))
    z, r_final, free_a = fa.x, fa.residuals_after.reshape(nk), fa.free
    A = aug.jacobian(z, table)[:, :, free_a].reshape(nk, -1)
    std = fa.std
    # degrees of freedom of each variance estimate (the intervals are t-based): i.i.d. errors n − p
    par_dof = np.full(z.size, float(max(nk - int(free_a.sum()), 1)))
    if cl is not None:  # errors correlated within a cluster: cluster-robust (CR2 sandwich) standard errors
        std = np.zeros_like(fa.std)
        # under the noise model of the selection (each measurement's noise shape) when there is one
        work = None if nm is None else measurement_covariance(src, nm.variances)
        std[free_a], par_dof[free_a] = augmented.cluster_robust_std(A, r_final, cl, work)
    if ad.shared_error is not None:  # errors shared within groups: sandwich covariance (honest std)
        cov, _, nu = augmented.shared_error_covariance(A, r_final, *ad.shared_error)
        std = np.zeros_like(z)
        std[free_a] = np.sqrt(np.clip(np.diag(cov), 0, None))
        par_dof[free_a] = nu
    z, std = aug.physical(z), aug.physical(std)  # A stays per fitted (scaled) unit
    return Refit(z, r_final, A, std, par_dof, fa.sigma, free_a, frozen)


def _family_frequency(lib: list, i: int, testable: list[int], boot: np.ndarray) -> float:
    """How often the bootstrap re-selects effect i in any of its forms (`forms`: a resample picks one
    form of a family, and which one is the held-out choice's business, not the selection's)."""
    fam = [c for c, j in enumerate(testable) if lib[j].family == lib[i].family]
    return float(min(1.0, sum(boot[c] for c in fam))) if len(fam) > 1 else float(boot[testable.index(i)])


def finding_records(rf: Refit, table, ad, lib: list, accepted: list[int], steps: list, ng: int, k: int,
                    folds: list, after_cv: np.ndarray, gates: list, testable: list[int], alikes: dict,
                    robust_p: dict, boot: np.ndarray) -> tuple[list[dict], list[np.ndarray], dict]:
    """Step 5 (module docstring): (findings, contributions (n, k) m, {accepted effect: columns of A})."""
    z, A, r_final, std, par_dof, free_a = rf.z, rf.A, rf.r_final, rf.std, rf.par_dof, rf.free_a
    nk = r_final.size
    col_of = {}  # accepted effect -> columns of A
    pos = ng
    free_idx = np.cumsum(free_a) - 1
    for i in accepted:
        cols = [int(free_idx[pos + m]) for m in range(lib[i].k) if free_a[pos + m]]
        col_of[i] = cols
        pos += lib[i].k
    rss_full = float(r_final @ r_final)
    findings = []
    contributions = []  # (n, k) fitted contribution of each accepted effect, m
    pos = ng
    if rf.S is not None:  # the columns the refit held: the contributions are those it fitted
        S_final = np.split(rf.S, np.cumsum([lib[i].k for i in accepted])[:-1], axis=2)
    else:
        S_final = ad.signatures(z[:ng], table, tuple(lib[i] for i in accepted)) if accepted else []
    for st, i, Se in zip(steps, accepted, S_final):
        e = lib[i]
        keep_cols = np.setdiff1d(np.arange(A.shape[1]), col_of[i])
        A_wo = A[:, keep_cols]
        # residual without this effect, to first order: r_final minus its contribution, refit
        th = z[pos:pos + e.k]
        contrib = np.einsum("nkc,c->nk", Se, th)
        contributions.append(contrib)
        r_wo = r_final - contrib.reshape(nk)
        Q = orthonormal(A_wo)
        r_wo_p = project_out(r_wo[:, None], Q)[:, 0]
        rss_wo = float(r_wo_p @ r_wo_p)
        delta_bic = nk * np.log(max(rss_wo, 1e-300) / max(rss_full, 1e-300)) - e.k * np.log(nk)
        cv_wo = resampling.holdout(A_wo, r_wo, folds)
        findings.append({
            "effect": e.name, "location": str(e.location), **({"form": e.data["form"]} if "form" in e.data else {}),
            **({"source": e.data["source"]} if "source" in e.data else {}),
            "parameters": [{"name": p, "value": float(th[m]), "std": float(std[pos + m]), "unit": e.units[m],
                            "dof": _dof(par_dof[pos + m]),
                            "ci95": augmented.t_interval(float(th[m]), float(std[pos + m]), par_dof[pos + m])}
                           for m, p in enumerate(e.parameters)],
            "evidence": {"statistic": st.statistic, "statistic_kind": "grouped F", "dof": list(st.dof),
                         "p_value": st.p_holm, "p_value_raw": st.p_value,
                         **({"p_value_sign_flips": robust_p[i]} if i in robust_p else {}),
                         "delta_bic": float(delta_bic),
                         "cv_rms_before_m": resampling.rms(cv_wo), "cv_rms_after_m": resampling.rms(after_cv),
                         "bootstrap_frequency": _family_frequency(lib, i, testable, boot)},
            "absorbed_fraction": gates[i].absorbed_fraction,
            "look_alikes": [{"effect": lib[testable[c]].name, "location": str(lib[testable[c]].location),
                             "delta_chi2": dl, "advice": lib[testable[c]].advice}
                            for c, dl in alikes.get(testable.index(i), [])],
            "min_detectable": gates[i].min_detectable,
            "confidence": "high",
        })
        pos += e.k
    return findings, contributions, col_of
