"""The diagnosis, a pure function of (measurement model, diagnosis table): the document of
`DIR/diagnosis.json` (see docs/diagnose.md).

1. fit the geometry (nonlinear least squares, `identify.fit`);
2. build every library candidate's signature at the solution; gate: projected signature,
   minimum detectable size vs plausible size, confounding → `not_identifiable` with advice;
3. forward selection by grouped F with Holm's correction (family α);
4. joint nonlinear refit of geometry + accepted effects (parameters with 1σ);
5. confirm: grouped cross-validation on time blocks (same folds before/after), ΔBIC,
   bootstrap selection frequency;
6. lack-of-fit of the final residuals against smooth functions of each joint angle, time,
   approach speed → `unexplained` and where.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from pipeline.diagnose import confirm, lack_of_fit
from pipeline.diagnose.effects import Effect, signature, tip_speed_vector, touch_library
from pipeline.diagnose.select import forward_select, gate, orthonormal, project_out
from pipeline.identify.least_squares import Fit, FitOptions, fit, kfold_indices
from pipeline.models import serial_arm


MIN_BOOTSTRAP = 0.5  # a confident finding is re-selected in at least this share of resamples


@dataclass(frozen=True)
class Settings:
    """Diagnosis settings: family α of the selection and of the lack-of-fit test, folds, group
    size (consecutive measurements per cross-validation group), bootstrap resamples."""

    alpha: float = 0.01
    folds: int = 5
    block: int = 5
    n_boot: int = 40
    seed: int = 0
    max_terms: int = 8


def diagnose(model, table, *, jig_tolerance_m: float = 2e-5, x0: np.ndarray | None = None,
             settings: Settings = Settings(), library: list[Effect] | None = None,
             geometry_fit: Fit | None = None) -> dict:
    """Diagnose a touch campaign (module docstring).  `model` is a TouchModel; `table` a
    diagnosis table (`pipeline.diagnose.table`)."""
    t0 = time.perf_counter()
    s = settings
    arm = model.arm
    f = geometry_fit or fit(model, table, FitOptions(x0=x0))
    n = f.residuals_after.shape[0]
    x = f.x
    free = f.free
    names = f.names
    free_names = [nm for nm, k in zip(names, free) if k]
    Jf = model.jacobian(x, table)[:, 0, free]
    r = f.residuals_after[:, 0]
    dof = n - int(free.sum())
    sigma = f.sigma
    lib = library if library is not None else touch_library(arm, table, jig_tolerance_m)
    _, Jq = serial_arm.joint_jacobian(x, table["joint_positions"])
    S = [signature(e, arm, x, table, Jq) for e in lib]

    # 2. gate
    gates = gate(lib, S, Jf, free_names, sigma, s.alpha)
    testable = [i for i, g in enumerate(gates) if g.identifiable]
    Sp = [gates[i].projected for i in testable]
    tols = [lib[i].tolerance for i in testable]

    # 3. forward selection
    steps = forward_select(r, Sp, dof, s.alpha, tols, s.max_terms)
    accepted = [testable[st.index] for st in steps]

    # 4. joint refit
    groups = confirm.time_blocks(table["time_since_start_s"], s.block)
    folds = kfold_indices(n, s.folds, s.seed, groups)
    before_cv = confirm.holdout(Jf, r, folds)
    aug = confirm.AugmentedModel(model, tuple(lib[i] for i in accepted))
    if accepted:
        z0 = np.concatenate([x, np.zeros(sum(lib[i].k for i in accepted))])
        fa = fit(aug, table, FitOptions(x0=z0))
        z, r_final, free_a = fa.x, fa.residuals_after[:, 0], fa.free
        A = aug.jacobian(z, table)[:, 0, free_a]
        std = fa.std
        sigma_after = fa.sigma
    else:
        z, r_final, A, std, sigma_after, free_a = x, r, Jf, f.std, sigma, free
    after_cv = confirm.holdout(A, r_final, folds)

    # 5. evidence per finding: ablation CV, ΔBIC, bootstrap
    boot = (confirm.bootstrap_frequency(Jf, r, Sp, tols, groups, s.alpha, s.n_boot, s.seed)
            if accepted and s.n_boot else np.zeros(len(testable)))
    ng = len(names)
    col_of = {}  # accepted effect -> columns of A
    pos = ng
    free_idx = np.cumsum(free_a) - 1
    for i in accepted:
        cols = [int(free_idx[pos + m]) for m in range(lib[i].k) if free_a[pos + m]]
        col_of[i] = cols
        pos += lib[i].k
    rss_full = float(r_final @ r_final)
    findings = []
    pos = ng
    for st, i in zip(steps, accepted):
        e = lib[i]
        keep_cols = np.setdiff1d(np.arange(A.shape[1]), col_of[i])
        A_wo = A[:, keep_cols]
        # residual without this effect, to first order: r_final minus its contribution, refit
        th = z[pos:pos + e.k]
        r_wo = r_final - (signature(e, arm, z[:ng], table) @ th)
        Q = orthonormal(A_wo)
        r_wo_p = project_out(r_wo[:, None], Q)[:, 0]
        rss_wo = float(r_wo_p @ r_wo_p)
        delta_bic = n * np.log(max(rss_wo, 1e-300) / max(rss_full, 1e-300)) - e.k * np.log(n)
        cv_wo = confirm.holdout(A_wo, r_wo, folds)
        findings.append({
            "effect": e.name, "location": str(e.location),
            "parameters": [{"name": p, "value": float(th[m]), "std": float(std[pos + m]), "unit": e.units[m]}
                           for m, p in enumerate(e.parameters)],
            "evidence": {"statistic": st.statistic, "statistic_kind": "grouped F", "dof": list(st.dof),
                         "p_value": st.p_holm, "p_value_raw": st.p_value, "delta_bic": float(delta_bic),
                         "cv_rms_before_m": confirm.rms(cv_wo), "cv_rms_after_m": confirm.rms(after_cv),
                         "bootstrap_frequency": float(boot[testable.index(i)])},
            "absorbed_fraction": gates[i].absorbed_fraction,
            "min_detectable": gates[i].min_detectable,
            "confidence": "high",
        })
        pos += e.k

    # 6. lack of fit
    speed = None
    if "approach_joint_velocity" in table:
        v = tip_speed_vector(z[:ng], table)
        speed = np.linalg.norm(v, axis=1)
    variables = lack_of_fit.touch_variables(z[:ng], table, [j.name for j in arm.joints], speed)
    lof = lack_of_fit.test(r_final, A, variables, n - A.shape[1], s.alpha)
    where = [{"variable": t.variable, "p_value": t.p_holm, "statistic": t.statistic,
              "region": list(t.region) if isinstance(t.region, tuple) else t.region, "peak_m": t.peak_m}
             for t in sorted(lof, key=lambda t: t.p_value) if t.significant]
    flagged = {w["variable"] for w in where}
    for fd, i in zip(findings, accepted):
        ev = fd["evidence"]
        if ev["bootstrap_frequency"] < MIN_BOOTSTRAP or ev["cv_rms_after_m"] >= ev["cv_rms_before_m"]:
            fd["confidence"] = "low"
            fd["note"] = "selected in few bootstrap resamples or no held-out improvement"
        if lib[i].variable in flagged:
            fd["confidence"] = "low"
            fd["note"] = (f"structure remains in {lib[i].variable} that {lib[i].name} does not explain; "
                          "the effect may be something outside the library")

    not_ident = [{"effect": g.effect.name, "location": str(g.effect.location), "reason": g.reason,
                  "absorbed_by": g.absorbed_by, "absorbed_fraction": g.absorbed_fraction,
                  "min_detectable": g.min_detectable if np.isfinite(g.min_detectable) else None,
                  "plausible_max": g.effect.plausible, "unit": g.effect.units[0], "advice": g.effect.advice}
                 for g in gates if not g.identifiable]
    candidates = [{"effect": g.effect.name, "location": str(g.effect.location), "identifiable": g.identifiable,
                   "absorbed_fraction": g.absorbed_fraction,
                   "min_detectable": g.min_detectable if np.isfinite(g.min_detectable) else None,
                   "unit": g.effect.units[0], "plausible_max": g.effect.plausible} for g in gates]
    return {
        "system": model.system,
        "n_measurements": int(n),
        "sigma_m": float(sigma),
        "sigma_after_m": float(sigma_after),
        "alpha": s.alpha,
        "findings": findings,
        "not_identifiable": not_ident,
        "unexplained": bool(where),
        "unexplained_where": where,
        "lack_of_fit": [{"variable": t.variable, "p_value": t.p_holm, "statistic": t.statistic, "dof": list(t.dof)}
                        for t in lof],
        "holdout_rms_before_m": confirm.rms(before_cv),
        "holdout_rms_after_m": confirm.rms(after_cv),
        "cross_validation": {"folds": s.folds, "groups": f"time blocks of {s.block} consecutive measurements",
                             "seed": s.seed, "linearised_at": "the full-data solution"},
        "candidates": candidates,
        "geometry": {"names": names, "x": [float(v) for v in z[:ng]], "free": [bool(b) for b in free]},
        "elapsed_s": time.perf_counter() - t0,
    }
