"""Step 7 of the diagnosis: the visual proof and the document of `DIR/diagnosis.json`
(docs/guide/diagnose.md, "diagnosis.json"): findings with their added-variable plots, the located
structure with its plots, the re-simulated campaign, `not_identifiable`, the candidates, the
clustered-inference summary, the held-out RMS before / after and what the campaign could not have seen
(`unseen`)."""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.document import plots, unseen
from pipeline.diagnose.inference import resampling
from pipeline.diagnose.inference.projection import orthonormal


def not_identifiable(gates: list) -> list[dict]:
    """The candidates the gate set aside, with what absorbs them and the advice."""
    return [{"effect": g.effect.name, "location": str(g.effect.location), "reason": g.reason,
             "absorbed_by": g.absorbed_by, "absorbed_fraction": g.absorbed_fraction,
             "min_detectable": g.min_detectable if np.isfinite(g.min_detectable) else None,
             "plausible_max": g.effect.plausible, "unit": g.effect.units[0], "advice": g.effect.advice}
            for g in gates if not g.identifiable]


def candidates(gates: list) -> list[dict]:
    """Every library candidate with its gate figures."""
    return [{"effect": g.effect.name, "location": str(g.effect.location), "identifiable": g.identifiable,
             "absorbed_fraction": g.absorbed_fraction,
             "min_detectable": g.min_detectable if np.isfinite(g.min_detectable) else None,
             # the size whose expected statistic is the critical value (50 % power: the convention of a t-test's
             # 'minimum detectable' size, e.g. 3σ/‖P⊥S‖ at t = 3); min_detectable is at 80 % power
             "detection_threshold": g.threshold if np.isfinite(g.threshold) else None,
             "unit": g.effect.units[0], "plausible_max": g.effect.plausible} for g in gates]


def add_plots(ad, findings: list[dict], effects: list, contributions: list, where: list[dict], variables: list,
              r: np.ndarray, r_final: np.ndarray, A: np.ndarray, Jf: np.ndarray, n: int, k: int) -> dict:
    """Added-variable plots per finding, a plot per located variable; returns the re-simulation."""
    Qg = orthonormal(Jf)
    for fd, e, c in zip(findings, effects, contributions):
        fd["plots"] = plots.added_variable(e, ad.located(e), r.reshape(n, k), r_final.reshape(n, k), c, Qg)
    for w in where:
        v = next(vv for vv in variables if vv.name == w["variable"])
        w["plots"] = plots.unexplained(v, r.reshape(n, k), r_final.reshape(n, k), A, k)
    return plots.resimulation(ad.time_s, r.reshape(n, k), r_final.reshape(n, k), contributions)


def clustered_summary(W, nm, s, ad, lib: list, dropped: list[int]) -> dict:
    """The `clustered_inference` entry (pose-clustered campaigns)."""
    return {
        "clusters": W.n_clusters, "sigma_within_m": W.sigma_within, "effective_rows": W.n_effective,
        "noise_variances": None if nm is None else [float(v) for v in nm.variances],
        "method": "random-effects whitening per cluster (select.cluster_whitener), iterated; within noise from the maximal model",
        "findings_check": (f"restricted wild cluster bootstrap ({s.sign_flips} sign draws per cluster) of each finding given "
                           "the others, Holm (select.cluster_sign_flip_p)" if s.sign_flips else None),
        "dropped_by_check": [{"effect": lib[i].name, "location": str(lib[i].location)} for i in dropped],
        "lack_of_fit_reference": ("parametric bootstrap under the adapter's physical cluster-error model (REML variances; "
                                  "diagnose.physical_lack_of_fit)" if ad.cluster_model is not None and nm is not None
                                  else "restricted wild cluster bootstrap (sign flips)")}


def assemble(*, system: str, n: int, k: int, sigma: float, sigma_after: float, s, clustered: dict | None,
             status: tuple[str, str], floor: dict | None, findings: list, rejected: list, carried: dict | None,
             gates: list, where: list, lof: list, before_cv: np.ndarray, after_cv: np.ndarray, all_cv: float,
             names: list, z: np.ndarray, free: np.ndarray, resim: dict, moved: int = 0,
             alone: list | None = None, design: dict | None = None) -> dict:
    """The diagnosis document (no wall-clock time: bit-identical across runs)."""
    ng = len(names)
    return {
        "system": system,
        "n_measurements": int(n),
        "residual_dim": int(k),
        "sigma_m": float(sigma),
        "sigma_after_m": float(sigma_after),
        "alpha": s.alpha,
        **({} if clustered is None else {"clustered_inference": clustered}),
        "status": status[0],
        "status_reason": status[1],
        "noise_floor": floor,
        "findings": findings,
        "rejected_findings": rejected,
        **({} if carried is None else {"_carried": carried}),
        "not_identifiable": not_identifiable(gates),
        "unexplained": bool(where),
        "unexplained_where": where,
        "lack_of_fit": [{"variable": t.variable, "p_value": t.p_holm, "statistic": t.statistic, "dof": list(t.dof)}
                        for t in lof],
        "holdout_rms_before_m": resampling.rms(before_cv),
        "holdout_rms_after_m": resampling.rms(after_cv),
        "holdout_rms_with_all_selected_m": all_cv,
        "cross_validation": {"folds": s.folds, "groups": f"time blocks of {s.block} consecutive measurements",
                             "seed": s.seed, "linearised_at": "the full-data solution",
                             **({"repaired": f"{moved} measurement(s) moved between folds so every training set keeps "
                                             "every face, placement, joint range and parameter direction"}
                                if moved else {}),
                             **({"unpredictable_measurements": alone,
                                 "unpredictable_note": "each carries a parameter direction alone (own leverage "
                                                       "> 0.99): no fit without it predicts it; it is in every "
                                                       "training set and out of the held-out figures"}
                                if alone else {})},
        **({"holdout_over_insample": design} if design and design["flagged"] else {}),
        "candidates": candidates(gates),
        "unseen": unseen.unseen(gates, findings, system),
        "geometry": {"names": names, "x": [float(v) for v in z[:ng]], "free": [bool(b) for b in free]},
        "resimulation": resim,
    }
