"""The diagnosis, a pure function of (measurement model, diagnosis table): the document of
`DIR/diagnosis.json` (see docs/guide/diagnose.md).

1. fit the geometry (nonlinear least squares, `identify.fit`);
2. build every library candidate's signature at the solution; gate: projected signature,
   minimum detectable size vs plausible size, confounding → `not_identifiable` with advice;
3. forward selection by grouped F with Holm's correction (family α);
4. joint nonlinear refit of geometry + accepted effects (parameters with 1σ);
5. evidence: grouped cross-validation on time blocks (same folds before/after; folds repaired so every
   training set keeps every face, placement, joint range and parameter direction, `identify.folds`),
   ΔBIC, bootstrap selection frequency;
6. lack-of-fit of the final residuals against smooth functions of each joint angle, time,
   approach speed (and, for touch campaigns, `adapters.touch_variables`) → `unexplained` and where;
7. the verdict (`verdict.arbiter`, `verdict.checks`): the held-out arbiter, findings carried by one or
   two records (`verdict.outliers` runs the diagnosis again without them), misspecification along
   each finding's own variable, twins, back to the declared noise floor, a held-out error many times
   the in-sample σ (`resampling.holdout_over_insample`: never `clean`/`explained` beside it) → `status`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
import scipy.stats

from pipeline.blas import one_thread
from pipeline.diagnose.adapters.adapter import Adapter
from pipeline.diagnose.adapters.touch import touch_adapter
from pipeline.diagnose.document.assemble import add_plots, assemble, clustered_summary
from pipeline.diagnose.inference import forms, refit, resampling, screen
from pipeline.diagnose.inference.projection import orthonormal, project_out
from pipeline.diagnose.inference.stepwise import LOOK_ALIKE_SHARE, look_alikes
from pipeline.diagnose.library.term import Effect
from pipeline.diagnose.library.touch_probe import tip_speed_vector
from pipeline.diagnose.verdict import arbiter, grading, outliers
from pipeline.identify.least_squares import Fit, FitOptions, fit
from pipeline.progress import step


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
    sign_flips: int = 9999  # with clusters: draws of the findings' cluster-robust check (0: off)
    # the robot's declared repeatability (3σ, m; ISO 9283 datasheet figure): the noise floor the
    # residuals are compared with (None: not declared, the back-to-the-floor check is not made)
    repeatability_3sigma_m: float | None = None


def diagnose(model, table, *, jig_tolerance_m: float = 2e-5, x0: np.ndarray | None = None,
             settings: Settings = Settings(), library: list[Effect] | None = None,
             geometry_fit: Fit | None = None, adapter: Adapter | None = None) -> dict:
    """Diagnose a campaign (module docstring).  `model` is a measurement model; `table` a
    diagnosis table.  Without `adapter`, `model` is an arc-welder TouchModel and the table a
    touch diagnosis table (`pipeline.diagnose.adapters.touch_table`).  Vector residuals (residual_dim k > 1)
    are flattened measurement-major; cross-validation and bootstrap keep a measurement's k
    rows together.  Runs with one BLAS thread (`pipeline.blas`: small matrices)."""
    with one_thread():
        if adapter is not None:
            return _diagnose(model, table, jig_tolerance_m=jig_tolerance_m, x0=x0, settings=settings,
                             library=library, geometry_fit=geometry_fit, adapter=adapter)

        def run(tab, gf, x_start):
            return _diagnose(model, tab, jig_tolerance_m=jig_tolerance_m, x0=x_start, settings=settings,
                             library=library, geometry_fit=gf, adapter=None, influence=True)

        speed = ((lambda x, t: np.linalg.norm(tip_speed_vector(x, t), axis=1))
                 if "approach_joint_velocity" in table else None)
        return outliers.screened(run, model, table, x0=x0, geometry_fit=geometry_fit, alpha=settings.alpha,
                                 speed=speed)


def _diagnose(model, table, *, jig_tolerance_m: float, x0: np.ndarray | None, settings: Settings,
              library: list[Effect] | None, geometry_fit: Fit | None, adapter: Adapter | None,
              influence: bool = False) -> dict:
    s = settings
    ad = adapter or touch_adapter(model, table, jig_tolerance_m, library, s.repeatability_3sigma_m)
    # 1. the geometry, 2. every candidate's signature at its solution and the noise the tests assume
    step("geometric fit" if geometry_fit is None else "geometric fit (identify's)")
    f = _geometry(model, table, ad, x0, geometry_fit)
    step(f"signatures of {len(ad.library)} candidates")
    p = screen.problem(model, table, f, ad)
    nz = screen.noise_model(ad, f.x, p)
    # 3. gate and selection (iterated with the noise model), each finding's form by held-out error
    step(f"gate and selection of {len(p.lib)} candidates")
    sel = screen.select(p, nz, s)
    groups = np.repeat(resampling.time_blocks(ad.time_s, s.block), p.k)
    # folds that keep the selected model's design too: a contact that alone carries a direction of the geometry
    # and the selected effects (a stretched pose under the heaviest payload for a compliance) is in every training
    # set — its held-out error would be an extrapolation, not a test of the effect
    selected = np.hstack([p.Jf] + [p.S[i] for i in sel.accepted])
    folds, moved, alone = resampling.design_folds(p.n, p.k, s, ad.time_s, table, selected)
    if sel.accepted:
        folds, far = resampling.without_extrapolated(folds, selected, p.n, p.k)
        alone = sorted(set(alone) | set(far))
    form_cv = _choose_forms(p, nz, sel, folds)
    # names the campaign cannot tell from each finding's: a swap the fit cannot reject at the diagnosis's level, or
    # one explaining nearly all the finding explains
    alikes = (look_alikes(sel.r_w, sel.Sp, p.dof, [sel.testable.index(i) for i in sel.accepted], sel.tols,
                          level=1 - s.alpha) if sel.accepted else {})
    # 4. joint refit, 5. evidence per finding (ablation CV, ΔBIC, bootstrap)
    before_cv = resampling.holdout(p.Jf, p.r, folds)
    step(f"joint refit of {len(sel.accepted)} finding(s)")
    rf = refit.joint_refit(model, table, f, ad, adapter, p.lib, sel.accepted, p.Jf, p.r, p.dof, nz.cl, nz.nm, nz.src,
                           p.S)
    after_cv = resampling.holdout(rf.A, rf.r_final, folds)
    step("bootstrap of the selection")
    boot = (resampling.bootstrap_frequency(sel.Jf_w, sel.r_w, sel.Sp, sel.tols, groups, s.alpha, s.n_boot, s.seed)
            if sel.accepted and s.n_boot else np.zeros(len(sel.testable)))
    ng = len(f.names)
    findings, contributions, col_of = refit.finding_records(
        rf, table, ad, p.lib, sel.accepted, sel.steps, ng, p.k, folds, after_cv, sel.gates, sel.testable, alikes,
        sel.robust_p, boot)
    for fd, i in zip(findings, sel.accepted):
        if i in form_cv:
            fd["evidence"]["forms_cv_rms_m"] = form_cv[i]
    _runner_ups(findings, sel, p)
    _alike_evidence(findings, sel, p, folds, s.alpha)
    _untested_alikes(findings, sel, p, folds)
    # 6. the held-out arbiter and the records that carry a finding (`verdict.arbiter`); pose-clustered
    # campaigns: the unweighted CV ignores the shared pose errors, so there the findings rest on the
    # pose sign-flip check instead and a finding without CV improvement is graded `low`
    fin = arbiter.Final(findings, sel.accepted, contributions, col_of, rf.A, rf.r_final, after_cv)
    W = nz.W
    fin, rejected, worse, all_cv = (arbiter.arbiter(fin, folds, p.Jf, p.r, before_cv) if W is None
                                    else (fin, [], False, resampling.rms(after_cv)))
    carried = arbiter.carried(fin, p.k, s.alpha) if influence and W is None else {}
    # lack of fit, the confidence of each name, back to the floor (`verdict.grading`)
    nk = p.n * p.k
    step("lack of fit and verdict")
    variables, lof, where = grading.locate(ad, rf.z[:ng], fin.r_final, fin.A, W, nk, s.alpha, s.seed, nz.src, nz.nm,
                                           nz.cl, nz.M)
    effects = [p.lib[i] for i in fin.accepted]
    misfit = grading.grade(fin.findings, effects, fin.contributions, [fin.col_of[i] for i in fin.accepted], fin.A,
                           fin.r_final, variables, where, sel.gates, W, s.alpha)
    design = resampling.holdout_over_insample(before_cv, fin.after_cv, p.sigma, rf.sigma_after)
    floor, st_name, st_reason = grading.floor_and_status(ad, rf.z[:ng], fin.r_final, fin.A, fin.after_cv, folds,
                                                         fin.findings, where, worse, misfit, s.alpha, design)
    # 7. visual proof (added-variable plots, the re-simulated campaign: pure arrays) and the document
    resim = add_plots(ad, fin.findings, effects, fin.contributions, where, variables, p.r, fin.r_final, fin.A, p.Jf,
                      p.n, p.k)
    doc = assemble(
        system=model.system, n=p.n, k=p.k, sigma=p.sigma, sigma_after=rf.sigma_after, s=s,
        clustered=None if W is None else clustered_summary(W, nz.nm, s, ad, p.lib, sel.dropped),
        status=(st_name, st_reason), floor=floor, findings=fin.findings, rejected=rejected,
        carried=carried if influence else None, gates=sel.gates, where=where, lof=lof, before_cv=before_cv,
        after_cv=fin.after_cv, all_cv=all_cv, names=f.names, z=rf.z, free=f.free, resim=resim, moved=moved,
        alone=alone, design=design)
    if influence:  # the final design and residual: the records' screen judges them against this model
        doc["_final"] = (fin.A, fin.r_final)
    return doc


def _geometry(model, table, ad: Adapter, x0: np.ndarray | None, geometry_fit: Fit | None) -> Fit:
    """Step 1: the geometric fit, unless given.  The weak gauges the adapter holds stay at the model's
    nominal (`Adapter.held`): freed because a term lowers the cost, they would absorb that term
    before it is tested."""
    if geometry_fit is None and ad.held:
        names0 = list(model.parameter_names())
        idx = [names0.index(h) for h in ad.held]
        x0 = np.array(model.initial_guess(table) if x0 is None else x0, float)
        x0[idx] = model.nominal()[idx]
        geometry_fit = fit(model, table, FitOptions(x0=x0, fixed=tuple(ad.held)))
    return geometry_fit or fit(model, table, FitOptions(x0=x0))


def _runner_ups(findings: list, sel: screen.Selection, p: screen.Problem) -> None:
    """A finding acting through a joint lists its runner-up: the candidate whose swap for it fits best
    (`stepwise.look_alikes` at level 1: every candidate with no more directions, closest first, outside its
    own family of forms), Δχ² how much worse — a reader sees how far the next name is even when it is beyond the look-alike bound."""
    joint = [j for j, i in enumerate(sel.accepted) if re.match(r"J\d", str(p.lib[i].location))]
    if not joint:
        return
    pos = [sel.testable.index(i) for i in sel.accepted]
    every = look_alikes(sel.r_w, sel.Sp, p.dof, pos, sel.tols, level=1.0, share=0.0)
    for j in joint:  # another form of its own family is not a rival name (`inference.forms` chose among them)
        near = [(c, dl) for c, dl in every.get(pos[j], [])
                if p.lib[sel.testable[c]].family != p.lib[sel.accepted[j]].family]
        if near:
            c, dl = near[0]
            e = p.lib[sel.testable[c]]
            findings[j]["runner_up"] = {"effect": e.name, "location": str(e.location), "delta_chi2": dl}


def _alike_evidence(findings: list, sel: screen.Selection, p: screen.Problem, folds: list, alpha: float) -> None:
    """Each look-alike with its evidence beside the finding's: the grouped cross-validated RMS of the linearised
    model with it in the finding's place (`cv_rms_m`; the finding's own: `evidence.cv_rms_linearised_m`) and the
    share of the finding's own gain it explains.  A rival the fit cannot reject at the diagnosis's level (Δχ² below
    χ²_k(1 − α)) stays a look-alike; a near-collinear one (explaining ≥ 90 % of the finding's gain,
    `stepwise.LOOK_ALIKE_SHARE`) stays one unless the data separate them — the fit rejects the swap at that level
    and the finding's held-out error is lower by more than two standard errors of the paired difference: the
    held-out arbiter decides where the data separate them, never the order of the library."""
    if not any(fd.get("look_alikes") for fd in findings):
        return
    label = {(p.lib[i].name, str(p.lib[i].location)): i for i in sel.testable}
    for j, fd in enumerate(findings):
        if not fd.get("look_alikes") or j >= len(sel.accepted):
            continue
        own = forms._cv(p.Jf, p.S, sel.accepted, p.r, folds) ** 2
        fd["evidence"]["cv_rms_linearised_m"] = float(np.sqrt(np.mean(own)))
        kb = p.lib[sel.accepted[j]].k
        kept = []
        for a in fd["look_alikes"]:
            c = label.get((a["effect"], a["location"]))
            if c is None:
                continue
            swap = sel.accepted[:j] + [c] + sel.accepted[j + 1:]
            e2 = forms._cv(p.Jf, p.S, swap, p.r, folds) ** 2
            d = e2 - own
            a["cv_rms_m"] = float(np.sqrt(np.mean(e2)))
            separated = np.mean(d) > 2 * np.std(d, ddof=1) / np.sqrt(d.size)
            if a["delta_chi2"] < scipy.stats.chi2.ppf(1 - alpha, kb):
                a["why"] = "the fit cannot reject the swap"
            elif separated:
                continue  # near-collinear, but the held-out error prefers the finding: not a look-alike
            else:
                a["why"] = "near-collinear here, and the held-out error does not separate them"
            kept.append(a)
        fd["look_alikes"] = kept


def _untested_alikes(findings: list, sel: screen.Selection, p: screen.Problem, folds: list) -> None:
    """A candidate the gate set aside — too weak along one direction of its parameters to be tested at a plausible
    size, not a twin — that reproduces a finding's fitted contribution (all but `LOOK_ALIKE_SHARE` of it, ⊥ the
    geometry and the other findings) is listed as `untested_look_alikes`: the campaign could not test it, and it
    would explain this finding as well (a J2 transmission error standing for a J2 eccentricity the geometry all but
    absorbs), so the name is not a confident one.  Each carries its evidence beside the finding's, as a tested
    look-alike does: `delta_chi2` (its swap for the finding, χ²-scaled; negative: it fits better) and `cv_rms_m`
    (the held-out RMS of the linearised model with it in the finding's place; the finding's own:
    `evidence.cv_rms_linearised_m`) — the reader sees which of the two the data lean to."""
    if not sel.accepted:
        return
    pos = [sel.testable.index(i) for i in sel.accepted]
    B = np.hstack([sel.Sp[c] for c in pos])
    coef, *_ = np.linalg.lstsq(B, sel.r_w, rcond=None)
    at = np.cumsum([0] + [sel.Sp[c].shape[1] for c in pos])
    aside = [(i, g) for i, g in enumerate(sel.gates) if not g.identifiable and np.any(g.projected)
             and not g.effect.data.get("blocked") and not g.reason.startswith("indistinguishable")]
    for j, fd in enumerate(findings[:len(pos)]):
        u = sel.Sp[pos[j]] @ coef[at[j]:at[j + 1]]
        others = [sel.Sp[c] for c in pos if c != pos[j]]
        if others:
            u = project_out(u[:, None], orthonormal(np.hstack(others)))[:, 0]
        uu = float(u @ u)
        if uu <= 0:
            continue
        own = (fd["effect"], fd["location"].split(" (")[0])
        hits = []
        for i, g in aside:
            if (g.effect.name, str(g.effect.location).split(" (")[0]) == own:
                continue
            Q = orthonormal(g.projected)
            share = float(np.sum((Q.T @ u) ** 2) / uu)
            swap = sel.accepted[:j] + [i] + sel.accepted[j + 1:]
            if share >= 1 - LOOK_ALIKE_SHARE:
                hits.append({"effect": g.effect.name, "location": str(g.effect.location), "explains": share,
                             "why": f"set aside by the gate ({g.reason}), yet it reproduces this finding",
                             "advice": g.effect.advice, **_swap_evidence(sel, p, folds, pos, j, g.projected, swap)})
            elif (g.reason.startswith("smallest detectable size") and g.min_detectable <= WEAK_FACTOR * g.effect.plausible
                  and _swap_fits_better(sel, p, pos, j, g.projected)):
                # too weak to be tested at a plausible size (but detectable within WEAK_FACTOR of it), yet in the
                # finding's place it fits the data better: the effect may be that one, larger than the library deems
                # plausible — not a confident name
                hits.append({"effect": g.effect.name, "location": str(g.effect.location), "explains": share,
                             "why": f"set aside by the gate ({g.reason}), yet in this finding's place it fits better",
                             "advice": g.effect.advice, **_swap_evidence(sel, p, folds, pos, j, g.projected, swap)})
        if hits:
            if "cv_rms_linearised_m" not in fd["evidence"]:
                fd["evidence"]["cv_rms_linearised_m"] = float(np.sqrt(np.mean(
                    forms._cv(p.Jf, p.S, sel.accepted, p.r, folds) ** 2)))
            fd["untested_look_alikes"] = sorted(hits, key=lambda h: -h["explains"])


WEAK_FACTOR = 10.0  # a set-aside candidate detectable within this factor of its plausible size may still be the effect
# (beyond it the campaign all but absorbs it: a Delta's tracker scale, detectable at 1 000× its plausible 100 ppm)


def _swap_fits_better(sel: screen.Selection, p: screen.Problem, pos: list, j: int, Sp_c: np.ndarray) -> bool:
    """The candidate (projected signature `Sp_c`) in the j-th finding's place leaves a smaller residual than the
    findings do (Δχ² < 0, `_swap_evidence`)."""
    return _rss(sel, [sel.Sp[c] for c in pos[:j] + pos[j + 1:]] + [Sp_c])[0] < _rss(sel, [sel.Sp[c] for c in pos])[0]


def _rss(sel: screen.Selection, blocks: list) -> tuple[float, int]:
    """(residual sum of squares of the selection's whitened residual off the span of `blocks`, that span's rank)."""
    X = orthonormal(np.hstack(blocks))
    e = sel.r_w - X @ (X.T @ sel.r_w)
    return float(e @ e), X.shape[1]


def _swap_evidence(sel: screen.Selection, p: screen.Problem, folds: list, pos: list, j: int, Sp_c: np.ndarray,
                   swap: list) -> dict:
    """{delta_chi2, cv_rms_m} of a candidate (projected signature `Sp_c`, on the problem the selection tested)
    in the place of the j-th finding (`pos`: the findings' places among the testable): Δχ² = (RSS with it − RSS
    of the findings)/σ̂², σ̂² the findings' residual variance; the held-out RMS of the linearised model `swap`."""
    rss_a, rk = _rss(sel, [sel.Sp[c] for c in pos])
    rss_s, _ = _rss(sel, [sel.Sp[c] for c in pos[:j] + pos[j + 1:]] + [Sp_c])
    s2 = max(rss_a / max(p.dof - rk, 1), 1e-300)
    return {"delta_chi2": (rss_s - rss_a) / s2,
            "cv_rms_m": float(np.sqrt(np.mean(forms._cv(p.Jf, p.S, swap, p.r, folds) ** 2)))}


def _choose_forms(p: screen.Problem, nz: screen.Noise, sel: screen.Selection, folds: list) -> dict:
    """Each finding's functional form among its family's forms: the held-out error decides
    (`inference.forms`; independent errors only).  Returns {library index: forms tried}."""
    if nz.W is not None or not sel.accepted:
        return {}
    chosen, form_cv = forms.choose(p.lib, sel.accepted, sel.testable, p.S, p.Jf, p.r, folds)
    if chosen != sel.accepted:
        sel.restrict(p, chosen)
    return form_cv
