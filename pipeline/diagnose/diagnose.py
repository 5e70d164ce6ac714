"""The diagnosis, a pure function of (measurement model, diagnosis table): the document of
`DIR/diagnosis.json` (see docs/guide/diagnose.md).

1. fit the geometry (nonlinear least squares, `identify.fit`);
2. build every library candidate's signature at the solution; gate: projected signature,
   minimum detectable size vs plausible size, confounding → `not_identifiable` with advice;
3. forward selection by grouped F with Holm's correction (family α);
4. joint nonlinear refit of geometry + accepted effects (parameters with 1σ);
5. confirm: grouped cross-validation on time blocks (same folds before/after), ΔBIC,
   bootstrap selection frequency;
6. lack-of-fit of the final residuals against smooth functions of each joint angle, time,
   approach speed (and, for touch campaigns, `lof_variables`) → `unexplained` and where;
7. the verdict (issue 18, `judge` / `verdict`): the held-out arbiter, findings carried by one or
   two records (`outliers` runs the diagnosis again without them), misspecification along each
   finding's own variable, twins, back to the declared noise floor → `status`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.blas import one_thread
from pipeline.diagnose import confirm, document, forms, grading, judge, outliers, refit
from pipeline.diagnose.adapter import Adapter, _extremeness, physical_lack_of_fit, physical_reference  # noqa: F401
from pipeline.diagnose.effects import Effect, tip_speed_vector
from pipeline.diagnose.grading import MIN_BOOTSTRAP  # noqa: F401  (re-exported)
from pipeline.diagnose.select import (Whitener, cluster_whitener, conditional_steps, forward_select, gate,
                                      look_alikes, measurement_whitener, noise_components, orthonormal,
                                      project_out, sigma_given, sign_flip_elimination)
from pipeline.diagnose.touch import touch_adapter  # noqa: F401  (re-exported)
from pipeline.identify.least_squares import Fit, FitOptions, fit, kfold_indices


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
    touch diagnosis table (`pipeline.diagnose.table`).  Vector residuals (residual_dim k > 1)
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
    if geometry_fit is None and ad.held:
        # the baseline every campaign gets (the clean one): a weak gauge freed because an effect
        # lowers the cost would absorb that effect before it is tested
        names0 = list(model.parameter_names())
        idx = [names0.index(h) for h in ad.held]
        x0 = np.array(model.initial_guess(table) if x0 is None else x0, float)
        x0[idx] = model.nominal()[idx]
        geometry_fit = fit(model, table, FitOptions(x0=x0, fixed=tuple(ad.held)))
    f = geometry_fit or fit(model, table, FitOptions(x0=x0))
    n, k = f.residuals_after.shape
    nk = n * k
    x = f.x
    free = f.free
    names = f.names
    free_names = [nm for nm, b in zip(names, free) if b]
    Jf = model.jacobian(x, table)[:, :, free].reshape(nk, -1)
    r = f.residuals_after.reshape(nk)
    dof = nk - int(free.sum())
    sigma = f.sigma
    lib = ad.library
    S3 = ad.signatures(x, table, tuple(lib))
    S = [sg.reshape(nk, -1) for sg in S3]

    # pose-clustered inference: the random-effects model of the cluster errors, estimated from the
    # geometric residuals and re-estimated once effects are accepted (iterated feasible GLS).  The
    # within-cluster noise (its variance components, and the σ of the minimum detectable sizes)
    # comes from the residuals of the maximal model — geometry + every library candidate — so
    # that an effect cannot inflate the noise it is tested against and hide in it
    Zc, cl = None, None
    if ad.cluster is not None:
        Zb = (ad.cluster_basis(x) if ad.cluster_basis is not None
              else np.broadcast_to(np.eye(k), (n, k, k)))
        Zc = np.asarray(Zb, float).reshape(nk, -1)
        cl = np.repeat(np.asarray(ad.cluster), k)
    M, eff_rows, nm, W, sigma_noise, src = None, None, None, None, None, None  # M: per-measurement noise shape (k×k)
    if Zc is not None:
        if ad.noise_shape is not None:
            r_max = project_out(r[:, None], orthonormal(np.hstack([Jf] + S)))[:, 0]
            src = ad.noise_shape(x)
            src = list(src) if isinstance(src, (list, tuple)) else [src]
            nm = noise_components(r_max, Zc, cl, src)
            M, eff_rows = measurement_whitener(src, nm.variances), nm.effective_rows
            W_max = cluster_whitener(r_max, Zc, cl, int(free.sum()) + sum(sg.shape[1] for sg in S), pre=M,
                                     effective_rows=eff_rows)
            sigma_noise = None if W_max is None else W_max.sigma_within

        W = cluster_whitener(r, Zc, cl, int(free.sum()), pre=M, effective_rows=eff_rows)
    if W is not None:  # residual degrees of freedom: only the dimensions that carry noise
        dof = W.n_effective - int(free.sum())

    gate_cache: dict = {}  # the gate's σ-free part (unwhitened problem: the same in every screen)

    def screen(W: Whitener | None, prior: list[int] | None = None):
        """2. gate and 3. selection, on the whitened problem when W is given; the gate's σ is the
        residual σ after the `prior` accepted effects (the geometry-only σ when there are none)."""
        if W is None:
            Jw, rw, Sw, sw = Jf, r, S, sigma
        else:
            Jw = W(Jf)
            rw = project_out(W(r)[:, None], orthonormal(Jw))[:, 0]
            Sw = [W(sg) for sg in S]
            # the noise, not the geometry-only residual (which holds any effect): from the maximal model
            sw = sigma_noise or W.sigma_within
        if prior and (W is None or sigma_noise is None):
            sw = sigma_given(rw, Jw, [Sw[i] for i in prior], dof)
        gs = gate(lib, Sw, Jw, free_names, sw, s.alpha, gate_cache if W is None else None)
        tst = [i for i, g in enumerate(gs) if g.identifiable]
        sp = [gs[i].projected for i in tst]
        tl = [lib[i].tolerance for i in tst]
        return gs, tst, sp, tl, forward_select(rw, sp, dof, s.alpha, tl, s.max_terms), Jw, rw

    # iterate: the gate's σ (and, with clusters, the whitener: feasible GLS) re-estimated from the
    # residuals after the accepted effects, until the accepted set no longer changes
    gates, testable, Sp, tols, steps, Jf_w, r_w = screen(W)
    accepted = [testable[st.index] for st in steps]
    for _ in range(3):
        if not accepted:
            break
        if W is not None:
            Dacc = np.hstack([Jf] + [S[i] for i in accepted])
            coef, *_ = np.linalg.lstsq(Dacc, r, rcond=None)
            W2 = cluster_whitener(r - Dacc @ coef, Zc, cl, Dacc.shape[1], pre=M, effective_rows=eff_rows)
            W = W2 if W2 is not None else W
        gates, testable, Sp, tols, steps, Jf_w, r_w = screen(W, accepted)
        new = [testable[st.index] for st in steps]
        done = sorted(new) == sorted(accepted)
        accepted = new
        if done:
            break

    # 3b. with clusters, the F tests rest on the whitener's model of the error within a pose; a
    # finding must also pass the cluster-robust sign-flip test (Holm), or it is dropped
    robust_p, dropped = {}, []
    if W is not None and accepted and s.sign_flips:
        accepted, robust_p, dropped = sign_flip_elimination(W, r, Jf_w, S, accepted, cl, len(testable), s.alpha,
                                                             s.sign_flips, s.seed)
        if dropped:
            steps = conditional_steps(r_w, Sp, dof, [testable.index(i) for i in accepted], tols, len(testable))
            accepted = [testable[st.index] for st in steps]

    groups = np.repeat(confirm.time_blocks(ad.time_s, s.block), k)
    folds = kfold_indices(nk, s.folds, s.seed, groups)
    # 3c. each finding's functional form among its family's forms: the held-out error decides (`forms`)
    form_cv: dict = {}
    if W is None and accepted:
        chosen, form_cv = forms.choose(lib, accepted, testable, S, Jf, r, folds)
        if chosen != accepted:
            steps = conditional_steps(r_w, Sp, dof, [testable.index(i) for i in chosen], tols, len(testable))
            accepted = [testable[st.index] for st in steps]

    # names the campaign cannot tell from each finding's (a swap that fits nearly as well)
    alikes = look_alikes(r_w, Sp, dof, [testable.index(i) for i in accepted], tols) if accepted else {}

    # 4. joint refit
    before_cv = confirm.holdout(Jf, r, folds)
    rf = refit.joint_refit(model, table, f, ad, adapter, lib, accepted, Jf, r, dof, cl, nm, src)
    z, A, r_final, sigma_after = rf.z, rf.A, rf.r_final, rf.sigma_after
    after_cv = confirm.holdout(A, r_final, folds)

    # 5. evidence per finding: ablation CV, ΔBIC, bootstrap
    boot = (confirm.bootstrap_frequency(Jf_w, r_w, Sp, tols, groups, s.alpha, s.n_boot, s.seed)
            if accepted and s.n_boot else np.zeros(len(testable)))
    ng = len(names)
    findings, contributions, col_of = refit.finding_records(rf, table, ad, lib, accepted, steps, ng, k, folds,
                                                            after_cv, gates, testable, alikes, robust_p, boot)
    for fd, i in zip(findings, accepted):
        if i in form_cv:
            fd["evidence"]["forms_cv_rms_m"] = form_cv[i]

    # 5b. the held-out arbiter (judge.arbiter) and the influence of single records (judge.carried)
    fin = judge.Final(findings, accepted, contributions, col_of, A, r_final, after_cv)
    # (pose-clustered campaigns: the unweighted CV ignores the shared pose errors, so there the findings
    # rest on the pose sign-flip check instead and a finding without CV improvement is graded `low`)
    fin, rejected, worse, all_cv = (judge.arbiter(fin, folds, Jf, r, before_cv) if W is None
                                    else (fin, [], False, confirm.rms(after_cv)))
    findings, accepted, contributions, col_of, A, r_final, after_cv = (
        fin.findings, fin.accepted, fin.contributions, fin.col_of, fin.A, fin.r_final, fin.after_cv)
    carried = judge.carried(fin, k, s.alpha) if influence and W is None else {}

    # 6. lack of fit, the confidence of each name, back to the floor (grading)
    variables, lof, where = grading.locate(ad, z[:ng], r_final, A, W, nk, s.alpha, s.seed, src, nm, cl, M)
    effects = [lib[i] for i in accepted]
    misfit = grading.grade(findings, effects, contributions, [col_of[i] for i in accepted], A, r_final, variables,
                           where, gates, W, s.alpha)
    floor, st_name, st_reason = grading.floor_and_status(ad, z[:ng], r_final, A, after_cv, folds, findings, where,
                                                         worse, misfit, s.alpha)
    # 7. visual proof (added-variable plots, the re-simulated campaign: pure arrays) and the document
    resim = document.add_plots(ad, findings, effects, contributions, where, variables, r, r_final, A, Jf, n, k)
    return document.assemble(
        system=model.system, n=n, k=k, sigma=sigma, sigma_after=sigma_after, s=s,
        clustered=None if W is None else document.clustered_summary(W, nm, s, ad, lib, dropped),
        status=(st_name, st_reason), floor=floor, findings=findings, rejected=rejected,
        carried=carried if influence else None, gates=gates, where=where, lof=lof, before_cv=before_cv,
        after_cv=after_cv, all_cv=all_cv, names=names, z=z, free=free, resim=resim)
