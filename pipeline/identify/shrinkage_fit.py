"""The shrinkage model choice as one fit: every gravity-compliance family tried (`physics_choice`), each
shrunk toward nominal by its prior — the prior's scale per parameter family chosen by the evidence
(`evidence.shrink_evidence`) or, where the rows come in
sessions / placements / sockets, by leaving out whole groups (`shrinkage_groups.shrink_by_groups`) — the best
family's MAP estimate returned as a `Fit` with its posterior covariance and its held-out residuals."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from pipeline.blas import single_threaded
from pipeline.identify.shrinkage import _anchor, _penalty, fold_holdout
from pipeline.identify.shrinkage_groups import shrink_by_groups


@single_threaded
def shrunk_fit(model, data, options, k: int = 5, seed: int = 0, progress=None):
    """(`Fit` of the MAP estimate, `Shrunk`, k-fold held-out residuals (n, residual_dim)).

    Start: the registration-only fit.  The fit's covariance, over the estimated parameters (registration ones the
    data cannot separate are held by the rank test): with the scales of the evidence (no groups) the posterior
    σ̂²(JᵀJ + Λ²)⁻¹ under them, the prior they estimate; with μ chosen by leaving out groups the second moment of
    the estimate's error under the stated prior (`accuracy.condition.shrunk_moment`) — μ is then what predicts
    the left-out groups best, not a prior, and the posterior at it claimed the robot known to the much narrower
    width it implies (MUKCa panda_2: new placements measured 2.2× the stated figure);
    each fold re-solves at the chosen μ, warm-started from the whole-data estimate."""
    import time

    from pipeline.accuracy.condition import shrunk_moment
    from pipeline.identify.complexity import fixed_for
    from pipeline.identify.identifiability import analyse
    from pipeline.identify.folds import design_folds
    from pipeline.identify.least_squares import Fit, fit
    from pipeline.identify.model import n_rows

    t0 = time.perf_counter()
    prior = options.prior_sigma
    if prior is None:
        from pipeline.accuracy.prior import prior_sigma

        prior = prior_sigma(model)[0]
    from pipeline.identify import physics_choice as pc
    from pipeline.identify.group_holdout import row_groups

    names = model.parameter_names()
    groups = [g for g in model.groups() if not g.startswith("_")]
    registration = set(model.groups().get("registration", []))
    n, kd = n_rows(data), model.residual_dim
    groups_of_rows = row_groups(model, data)
    tool = tool_candidates(model, data) if groups_of_rows is not None else ()
    scored, tried, regfits = [], {}, {}
    for chosen, stage in pc.stagings(model, grouped=groups_of_rows is not None):
        on, off = pc.names_of(model, chosen)
        label = pc.label(chosen, stage)
        staged = stage == pc.WITH_REGISTRATION
        reg_fixed = tuple((set(options.fixed) | set(fixed_for(model, ["registration", *(on if staged else ())])))
                          | set(off))
        key = frozenset(reg_fixed)  # the rigid candidate's registration-only fit serves every joint one
        f0 = regfits[key] = regfits.get(key) or fit(model, data, replace(options, fixed=reg_fixed))
        bad = pc.inadmissible(f0, on, model) if staged and not getattr(model, "forced", False) else []
        if bad:
            tried[label] = {"admissible": False, "negative": bad}
            if progress is not None:
                progress(f"physics {label}: not admissible (negative compliance {', '.join(bad)})")
            continue
        fixed = tuple(set(options.fixed) | set(fixed_for(model, groups)) | set(off))
        # registration parameters the data cannot tell apart stay at their registration-only values
        held = tuple(nm for i, nm in enumerate(names)
                     if not f0.free[i] and nm in registration | (set(on) if staged else set()))
        extra = on if staged else ()  # staged: anchored at the registration stage; else shrunk toward rigid
        if groups_of_rows is not None:  # whole groups left out: what carries over to a new session / placement
            s = shrink_by_groups(model, data, prior, f0.x, groups_of_rows, fixed=fixed + held, progress=progress,
                                 extra=on, tool=tool)
            score = s.gcv[s.mu_m]
        else:
            s, refused, neg = pc.shrink_physical(model, data, prior, f0.x, fixed + held, () if staged else on, extra,
                                                 progress)
            if neg:
                tried[label] = {"admissible": False, "negative": list(neg)}
                continue
            held += refused
            on = tuple(nm for nm in on if nm not in refused)
            m = n * kd  # GCV with staged physics terms counted as estimated (they were, at the registration stage)
            rss = s.gcv[s.mu_m] * (m - s.dof) ** 2 / m
            score = m * rss / max(m - s.dof - len(extra), 1e-9) ** 2
        tried[label] = {"admissible": True, "score_m2": float(score), "mu_m": float(s.mu_m),
                        **({"log_evidence": float(s.log_evidence)} if np.isfinite(s.log_evidence) else {})}
        if not staged and len(on) < len(pc.names_of(model, chosen)[0]):
            tried[label]["held_at_zero"] = [nm for nm in pc.names_of(model, chosen)[0] if nm not in on]
        if progress is not None and len(tried) > 1:
            progress(f"physics {label}: score {np.sqrt(score) * 1e3:.4g} mm")
        if groups_of_rows is None:  # each row's share of the score: the standard error of `simplest_within_noise`
            r2 = np.sum(np.asarray(model.residuals(s.x, data), float).reshape(n, kd) ** 2, axis=1)
            rows = r2 * score / max(float(np.mean(r2)), 1e-300)
        else:
            rows = np.full(n, score)
        scored.append((score, len(pc.names_of(model, chosen)[0]), rows,
                       dict(s=s, f0=f0, fixed=fixed, held=held, on=on, chosen=chosen, extra=extra, stage=stage,
                            label=label, shrunk=() if staged else on)))
    pick = pc.simplest_within_noise([c[:3] for c in scored]) if groups_of_rows is None else \
        min(range(len(scored)), key=lambda i: scored[i][0])
    if scored[pick][3]["stage"] == pc.WITH_GEOMETRY:  # verified by refitting on folds of rows against the best staged
        ref = min((i for i in range(len(scored)) if scored[i][3]["stage"] == pc.WITH_REGISTRATION),
                  key=lambda i: scored[i][0])
        from pipeline.identify.natural_groups import holdout_groups

        folds = design_folds(n, pc.CHECK_FOLDS, seed, holdout_groups(model, data), data)
        cv = {}
        for i in (pick, ref):
            c = scored[i][3]
            cv[i] = pc.fold_rms(model, data, prior, c["f0"].x, c["fixed"] + c["held"], c["shrunk"], c["extra"], folds)
            tried[c["label"]]["fold_rms_m"] = cv[i]
        if cv[pick] >= cv[ref]:
            tried[scored[pick][3]["label"]]["not_kept"] = (f"refitted on {len(folds)} folds of rows, it predicts them "
                                                           f"worse than {scored[ref][3]['label']}")
            pick = ref
    c = scored[pick][3]
    s, f0, fixed, held, on, chosen, extra, stage, label = (c[k] for k in ("s", "f0", "fixed", "held", "on", "chosen",
                                                                         "extra", "stage", "label"))
    least = min(scored, key=lambda c: c[0])[3]["label"]
    if least != label:  # a smaller model kept within the noise of the least score: said, with the one it beat
        tried[label]["kept_over"] = least
    if len(tried) > 1 or on:  # the chosen families, and how their terms were estimated (`physics_choice.stagings`)
        s = replace(s, physics={"chosen": "+".join(chosen) or "rigid", "terms": list(on), "candidates": tried,
                                **({"estimated": stage} if chosen else {})})
    if s.tool == "free":  # the left-out groups freed the tool point: it is estimated like the registration
        model = replace(model, fit_tool=True)
        fixed = tuple(nm for nm in fixed if nm not in tool)
    free_mask, w = _penalty(model, np.asarray(prior, float), fixed + held, extra)
    wa = w + _anchor(model, np.asarray(prior, float), fixed + held, extra)
    J = np.asarray(model.jacobian(s.x, data), float).reshape(n * kd, -1)
    mu_eff = 0.0 if np.isinf(s.mu_m) else s.mu_m
    lam_all = s.lam if s.lam is not None else np.where(free_mask, mu_eff * wa, 0.0)
    s = replace(s, lam=lam_all)
    if groups_of_rows is not None:
        holdout = s.holdout
    else:  # the folds of `least_squares.cross_validate`, each left out in closed form (no refit)
        from pipeline.identify.natural_groups import holdout_groups

        folds = design_folds(n, k, seed, holdout_groups(model, data), data)
        idx = np.flatnonzero(free_mask)
        r = np.asarray(model.residuals(s.x, data), float).ravel()
        holdout = fold_holdout(J[:, idx], r, lam_all[idx], folds, kd)
    est = free_mask & ~((w > 0) & np.isinf(s.mu_m))  # μ = ∞: the robot stays nominal
    ident = analyse(np.vstack([J, np.diag(lam_all)]), names, ~est, getattr(model, "priority", lambda: None)())
    r1 = np.asarray(model.residuals(s.x, data), float).reshape(n, kd)
    m, fr = r1.size, ident.free
    sigma = float(np.sqrt(np.sum(r1**2) / max(m - s.dof, 1)))
    if groups_of_rows is not None:  # μ chose what predicts left-out groups, not a prior: its posterior states nothing
        centre = np.where(w > 0, np.asarray(model.nominal(), float), f0.x)  # the prior's centre (registration: own fit)
        cov = shrunk_moment(J[:, fr], r1.ravel(), (s.x - centre)[fr], wa[fr], sigma)  # under the stated prior
    else:  # the evidence's scales are the prior estimated from the data: the posterior under them
        cov = sigma**2 * np.linalg.pinv(J[:, fr].T @ J[:, fr] + np.diag(lam_all[fr] ** 2), rcond=1e-12, hermitian=True)
    std = np.zeros(s.x.size)
    std[fr] = np.sqrt(np.clip(np.diag(cov), 0, None))
    for i in np.flatnonzero(free_mask & ~fr):
        ident.reasons[int(i)] = ("not fitted: registration only predicted the left-out groups best"
                                 if not est[i] else "not separable from the rest even with its prior")
    out = Fit(names=names, units=model.parameter_units(), nominal=f0.nominal, x=s.x, identifiability=ident, std=std,
              cov=cov, residuals_before=f0.residuals_before, residuals_after=r1, sigma=sigma,
              nfev=f0.nfev, elapsed_s=time.perf_counter() - t0)
    return out, s, holdout


def tool_candidates(model, data) -> tuple[str, ...]:
    """The tool point's parameters the model choice may free (`shrinkage_groups`): those of a model whose campaign
    left ``fit_tool`` unsaid (None) that the measurements depend on (a ball centre's translation, not the
    rotation of a point's frame); () for a model without that switch or with the campaign's explicit setting."""
    if not hasattr(model, "fit_tool") or getattr(model, "fit_tool") is not None:
        return ()
    names = model.parameter_names()
    known = set(model.groups().get("_known tool", []))
    J = np.asarray(model.jacobian(model.nominal(), data), float).reshape(-1, len(names))
    return tuple(nm for i, nm in enumerate(names) if nm in known and np.any(J[:, i] != 0))
