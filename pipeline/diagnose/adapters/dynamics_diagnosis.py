"""The diagnosis of a dynamics identification: the shared method on the dynamics adapter's problem.

1. the problem at the identified model (`adapters.dynamics.build`): the base regressor is the
   "geometry", rows weighted per joint and whitened along time;
2. gate and selection (`inference.screen.select`: projected signatures, minimum detectable sizes
   against plausible ones, forward selection by grouped F under Holm's correction), each finding's
   form by held-out error (`inference.forms`), the names the data can hardly tell apart
   (`stepwise.look_alikes`), bootstrap selection frequency over time blocks (`resampling`);
3. the joint refit of base parameters + findings (generalised least squares on the whitened rows:
   parameters with 1σ and 95 % intervals);
4. the held-out arbiter, in N·m on the raw torques: contiguous-block cross-validation with a guard band
   (`dynamics.crossval`, the arbiter of identification's own choices) of the base model, of the base
   model with the findings and of it without each finding — a finding that does not lower the held-out
   error by more than two standard errors of the drop's noise (over 2 s blocks, `gain_z`) is rejected; if the
   findings together make it worse, every one is;
5. where the rest is: lack of fit against each joint's velocity, position, load and time
   (`verdict.lack_of_fit`, on the whitened rows), the held-out error per joint, velocity regime, load
   and time quarter (`locate`); grading of each name (`verdict.grading`, `verdict.arbiter`); the status
   (`verdict.checks.status`); what the campaign could not see (the gate's `not_identifiable`), and what
   of the drives' scale it can (`drive_scale`).

The document's ``*_m`` figures are N·m here (``residual_unit``), as a camera's are pixels.
"""

from __future__ import annotations

import time

import numpy as np

from pipeline.diagnose.adapters import dynamics as A
from pipeline.diagnose.document.assemble import candidates, not_identifiable
from pipeline.diagnose.inference import forms, resampling, screen
from pipeline.diagnose.inference.augmented import t_interval
from pipeline.diagnose.inference.stepwise import look_alikes
from pipeline.diagnose.library import drive
from pipeline.diagnose.method import Settings
from pipeline.diagnose.verdict import arbiter, checks, grading, lack_of_fit
from pipeline.dynamics import crossval

GUARD_S = 0.5  # the held-out blocks' guard band (as identification's)
BOOT_BLOCK_S = 2.0  # bootstrap resampling unit and the held-out gain's blocks: time blocks of this length
MIN_GAIN_Z = 2.0  # a finding is kept when it lowers the held-out error by more than 2 standard errors


def _rows(samples: np.ndarray, F: int) -> np.ndarray:
    return (np.asarray(samples)[:, None] * F + np.arange(F)[None]).ravel()


def held_out(D: np.ndarray, y: np.ndarray, wr: np.ndarray, T: int, F: int, folds: int, guard: int) -> np.ndarray:
    """Held-out residuals (T, F), N·m, of the weighted least-squares model y ≈ D θ (rows sample-major, weights
    `wr`: 1/σ_j, 0 for a row the model does not fit), contiguous blocks with a guard band (`dynamics.crossval`):
    every row of a held-out block predicted.  Each fold's normal equations are the whole
    recording's less those of the rows it leaves out (one pass over the rows, not one per fold)."""
    Dw, yw = D * wr[:, None], y * wr
    c = Dw.shape[1]
    scale = np.sqrt(np.einsum("ij,ij->j", Dw, Dw))
    scale = np.where(scale > 0, scale, 1.0)
    Dw = Dw / scale
    G, h = Dw.T @ Dw, Dw.T @ yw
    out = np.empty((T, F))
    for blk in crossval.blocks(T, folds):
        lo, hi = max(blk[0] - guard, 0), min(blk[-1] + guard + 1, T)
        ex = slice(lo * F, hi * F)
        Ge, he = G - Dw[ex].T @ Dw[ex], h - Dw[ex].T @ yw[ex]
        th = np.linalg.lstsq(Ge + 1e-12 * np.trace(Ge) / c * np.eye(c), he, rcond=None)[0] / scale
        rs = slice(blk[0] * F, (blk[-1] + 1) * F)
        out[blk] = (y[rs] - D[rs] @ th).reshape(blk.size, F)
    return out


def gain_z(before: np.ndarray, after: np.ndarray, fs: float) -> float:
    """How surely a model lowers the held-out error beyond the measurement noise: the drop in held-out mean square
    over its noise's standard error, both over time blocks (`BOOT_BLOCK_S`: neighbouring samples' errors are not
    independent).  With the held-out residuals r₀ (before) and r₁ (after), Δ = r₀ − r₁ the model's held-out
    prediction, the drop r₀² − r₁² = 2·r₁·Δ + Δ²: its noise is the first part (what another recording of the same
    motion would change), the second is the model's effect itself, which is larger at some instants of the motion
    than at others (an elastic lag under the largest accelerations) without making the drop less sure — so the
    standard error is the scatter of the block means of 2·r₁·Δ.  Above `MIN_GAIN_Z` the drop is more than the
    noise's scatter.  A model that only fits noise has Δ² ≥ 0 against 2·r₁·Δ ≈ −2·Δ² held out: a negative drop."""
    n = max(int(round(BOOT_BLOCK_S * fs)), 1)
    d = np.mean(before**2 - after**2, axis=1)
    noise = np.mean(2.0 * after * (before - after), axis=1)
    m = d.size // n
    if m < 3:
        return float(np.sign(d.mean()) * np.inf) if d.mean() else 0.0
    gain = d[:m * n].reshape(m, n).mean(axis=1).mean()
    se = noise[:m * n].reshape(m, n).mean(axis=1).std(ddof=1) / np.sqrt(m)
    return float(gain / se) if se > 0 else float(np.sign(gain) * np.inf)


def _design(b: A.Built, idx: list[int]) -> np.ndarray:
    T, F = b.table["tau"].shape
    return np.hstack([b.X] + [b.S[i].reshape(T * F, -1) for i in idx])


OFFSET_ITERATIONS = 4  # fixed-point steps of the stream offset's refit (each a linear least squares)


def offset_refit(b: A.Built, acc: list[int], th: np.ndarray, yw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The joint refit with the stream offset δ refitted as what it is, a delay of the whole model: its column
    (τ̃(t − δ_f) − τ̃(t))/δ_f is rebuilt from the refitted model τ̃ — base parameters and every other finding, not
    the identified torque alone (a Stribeck bump the effort stream also delays belongs in it) — at δ_f = the
    current δ (the exact shift rather than the nearest form's secant), and the least squares solved again, until δ
    settles (`OFFSET_ITERATIONS`).  Updates the offset's signature in `b` (raw and whitened); (whitened design, θ)."""
    T, F = b.table["tau"].shape
    p = b.problem
    i = next(j for j in acc if p.lib[j].name == "time_offset")
    delay = float(p.lib[i].data.get("delay_s", 0.01))
    Aw = np.hstack([p.Jf] + [p.S[j] for j in acc])
    for _ in range(OFFSET_ITERATIONS):
        full, col, at = b.X @ th[:p.n_free], p.n_free, None
        for j in acc:
            k = p.lib[j].k
            if j == i:
                at = col
            else:
                full = full + b.S[j].reshape(T * F, -1) @ th[col:col + k]
            col += k
        delta = float(th[at])
        delay = delta if abs(delta) > 1e-4 else delay
        model = {"time_s": b.table["time_s"], "tau_fit": full.reshape(T, F)}
        b.S[i] = ((drive.shifted(model, delay) - model["tau_fit"]) / delay)[:, :, None]
        p.S[i] = b.W(b.S[i].reshape(T * F, -1))
        Aw = np.hstack([p.Jf] + [p.S[j] for j in acc])
        th, *_ = np.linalg.lstsq(Aw, yw, rcond=None)
        if abs(float(th[at]) - delta) < 1e-3 * max(abs(delta), 1e-6):
            break
    return Aw, th


def _words(text: str) -> str:
    """The shared gate's words for a dynamics model: what absorbs a term is the base parameters."""
    return str(text).replace("by the geometry", "by the base parameters")


def _one_form_per_family(lib: list, accepted: list[int]) -> list[int]:
    """The accepted terms with one form per family (the first selected): two forms of one term are one
    physics, and which form is the held-out choice's business (`inference.forms`)."""
    seen, out = set(), []
    for i in accepted:
        if lib[i].family not in seen:
            seen.add(lib[i].family)
            out.append(i)
    return out


def locate(tab: dict, before: np.ndarray, after: np.ndarray) -> list[dict]:
    """Held-out RMS (N·m) per fitted joint in velocity regimes (|v| below 2 %, 2–20 %, above 20 % of its
    largest speed), load terciles (|τ_rigid|) and time quarters, before and after the findings."""
    out = []
    t = tab["time_s"]
    quarter = np.minimum((4 * (t - t[0]) / max(np.ptp(t), 1e-9)).astype(int), 3)
    for f, name in enumerate(tab["joints"]):
        v = np.abs(tab["v"][:, f])
        s = v / max(v.max(), 1e-12)
        load = np.abs(tab["tau_rigid"][:, f])
        cuts = np.quantile(load, [1 / 3, 2 / 3])
        groups = {"velocity": [("near rest / reversal", s < 0.02), ("slow", (s >= 0.02) & (s < 0.2)), ("fast", s >= 0.2)],
                  "load": [("light", load < cuts[0]), ("medium", (load >= cuts[0]) & (load < cuts[1])),
                           ("heavy", load >= cuts[1])],
                  "time": [(f"quarter {k + 1}", quarter == k) for k in range(4)]}
        for kind, parts in groups.items():
            for label, m in parts:
                if m.sum() < 10:
                    continue
                out.append({"joint": name, "by": kind, "regime": label, "share": float(m.mean()),
                            "rms_before": crossval.rms(before[m, f]), "rms_after": crossval.rms(after[m, f])})
    return out


def _finding(b: A.Built, i: int, st, theta: np.ndarray, std: np.ndarray, dof: int, gate, alikes: list,
             cv_wo: float, cv_after: float, boot: float) -> dict:
    e = b.lib[i]
    return {"effect": e.name, "location": str(e.location), "joint": b.table["joints"][e.data["joint"]]
            if "joint" in e.data else None, **({"form": e.data["form"]} if "form" in e.data else {}),
            "parameters": [{"name": p, "value": float(theta[m]), "std": float(std[m]), "unit": e.units[m],
                            "dof": float(dof), "ci95": t_interval(float(theta[m]), float(std[m]), dof)}
                           for m, p in enumerate(e.parameters)],
            "evidence": {"statistic": st.statistic, "statistic_kind": "grouped F (whitened rows)", "dof": list(st.dof),
                         "p_value": st.p_holm, "p_value_raw": st.p_value, "cv_rms_before_m": cv_wo,
                         "cv_rms_after_m": cv_after, "bootstrap_frequency": boot},
            "absorbed_fraction": gate.absorbed_fraction, "min_detectable": gate.min_detectable,
            "size_over_min_detectable": float(np.max(np.abs(theta)) / gate.min_detectable)
            if np.isfinite(gate.min_detectable) and gate.min_detectable > 0 else None,
            "look_alikes": [{"effect": b.lib[c].name, "location": str(b.lib[c].location), "delta_chi2": dl,
                             "advice": b.lib[c].advice} for c, dl in alikes],
            "advice": e.advice, "confidence": "high"}


def drive_scale(b: A.Built, gates: list, findings: list[dict]) -> dict:
    """What the recording can tell of the drives' effort → torque constants (module docstring)."""
    per = []
    for g in gates:
        if g.effect.name != "drive_scale":
            continue
        fd = next((f for f in findings if f["effect"] == "drive_scale" and f["location"] == g.effect.location), None)
        per.append({"joint": g.effect.location, "identifiable": g.identifiable,
                    "absorbed_fraction": g.absorbed_fraction,
                    "min_detectable_relative": g.min_detectable if np.isfinite(g.min_detectable) else None,
                    "reason": _words(g.reason) or None,
                    "found": None if fd is None else fd["parameters"][0]})
    return {"per_joint": per, "common_scale": "not identifiable from these recordings: a scale shared by every "
            "drive scales every inertial parameter with it (the fit absorbs it whole); a known load fixes it — "
            "record the same excitation with a payload of known mass"}


def diagnose(rb, data, fit, settings: Settings = Settings(), progress=None) -> dict:
    """The diagnosis document of identification `fit` on `data` (module docstring); one BLAS thread."""
    from pipeline.blas import one_thread

    with one_thread():
        return _diagnose(rb, data, fit, settings, progress or (lambda s: None))


def _diagnose(rb, data, fit, settings: Settings, say) -> dict:
    t0 = time.perf_counter()
    b = A.build(rb, data, fit)
    p, tab = b.problem, b.table
    T, F = tab["tau"].shape
    fs = 1.0 / float(np.median(np.diff(tab["time_s"])))
    say(f"problem: {T} samples × {F} joints, {p.n_free} base parameters, {len(b.lib)} candidate terms")
    sel = screen.select(p, screen.Noise(), settings)
    row_folds = [_rows(blk, F) for blk in crossval.blocks(T, settings.folds)]
    form_cv = {}
    one = _one_form_per_family(p.lib, sel.accepted)
    if one != sel.accepted:
        sel.restrict(p, one)
    if sel.accepted:
        chosen, form_cv = forms.choose(p.lib, sel.accepted, sel.testable, p.S, p.Jf, p.r, row_folds)
        if chosen != sel.accepted:
            sel.restrict(p, chosen)
    pos = [sel.testable.index(i) for i in sel.accepted]
    # names the recording cannot tell from each finding's: a swap the fit cannot reject at the diagnosis's level
    alikes = look_alikes(sel.r_w, sel.Sp, p.dof, pos, sel.tols, level=1 - settings.alpha) if sel.accepted else {}
    boot = np.zeros(len(sel.testable))
    if sel.accepted and settings.n_boot:
        groups = np.repeat((tab["time_s"] // BOOT_BLOCK_S).astype(int), F)
        boot = resampling.bootstrap_frequency(p.Jf, p.r, [p.S[i] for i in sel.testable], sel.tols, groups,
                                              settings.alpha, settings.n_boot, settings.seed)
    say(f"selection: {len(sel.accepted)} finding(s) ({time.perf_counter() - t0:.1f} s)")
    # 3. joint refit on the whitened rows
    acc = list(sel.accepted)
    Aw = np.hstack([p.Jf] + [p.S[i] for i in acc])
    yw = b.W(b.y)
    th, *_ = np.linalg.lstsq(Aw, yw, rcond=None)
    if any(p.lib[i].name == "time_offset" for i in acc):
        Aw, th = offset_refit(b, acc, th, yw)
    rw = yw - Aw @ th
    dof = max(b.W.n_effective - np.linalg.matrix_rank(Aw), 1)
    s2 = float(rw @ rw) / dof
    cov = s2 * np.linalg.pinv(Aw.T @ Aw)
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    # 4. the held-out arbiter in N·m
    guard = int(round(GUARD_S * fs))
    wr = (1.0 / np.maximum(b.sigma_joint, 1e-12))[np.tile(np.arange(F), T)]
    wfit = wr * np.asarray(tab["fitted"], float).reshape(T * F)  # fitted on the rows identification fits, all scored
    before = held_out(b.X, b.y, wfit, T, F, settings.folds, guard)
    after = held_out(_design(b, acc), b.y, wfit, T, F, settings.folds, guard)
    without = {i: held_out(_design(b, [j for j in acc if j != i]), b.y, wfit, T, F, settings.folds, guard)
               for i in acc}
    findings, col = [], p.n_free
    col_of, contributions = {}, []
    for st, i in zip(sel.steps, acc):
        k = p.lib[i].k
        c = sel.testable.index(i)
        fam = [m for m, j in enumerate(sel.testable) if p.lib[j].family == p.lib[i].family]
        fd = _finding(b, i, st, th[col:col + k], std[col:col + k], dof, sel.gates[i], alikes.get(c, []),
                      crossval.rms(without[i]), crossval.rms(after), float(min(1.0, boot[fam].sum())))
        if i in form_cv:
            fd["evidence"]["forms_cv_rms_m"] = form_cv[i]
        findings.append(fd)
        col_of[i] = list(range(col, col + k))
        contributions.append((b.S[i].reshape(T * F, -1) @ th[col:col + k]).reshape(T, F))  # N·m
        col += k
    for fd, i in zip(findings, acc):
        fd["evidence"]["cv_gain_z"] = gain_z(without[i], after, fs)
    # a parameter only one sign of which is physics (a compliance, a friction growing with load), found with the
    # other sign beyond 2σ: not that physics — a proxy for something outside the library
    wrong_sign = {j for j, (fd, i) in enumerate(zip(findings, acc)) if p.lib[i].data.get("sign")
                  and p.lib[i].data["sign"] * fd["parameters"][0]["value"] < -2 * fd["parameters"][0]["std"]}
    rejected = [j for j, fd in enumerate(findings) if fd["evidence"]["cv_gain_z"] < MIN_GAIN_Z or j in wrong_sign]
    kept = [j for j in range(len(findings)) if j not in rejected]
    final_cv = after
    if rejected:
        final_cv = held_out(_design(b, [acc[j] for j in kept]), b.y, wfit, T, F, settings.folds, guard)
    worse = bool(kept) and crossval.rms(final_cv) > crossval.rms(before)
    if worse:
        rejected, kept, final_cv = list(range(len(findings))), [], before
    why = ("the model with the selected terms is worse out of sample than the identified model alone" if worse
           else f"modelling it does not lower the held-out torque error by more than {MIN_GAIN_Z:g} standard errors")
    sign_note = ("its sign is not that physics (a negative compliance, friction falling with load, a breakaway bump "
                 "below the Coulomb level): a proxy for something the library does not name")
    rejected_docs = [{**findings[j], "confidence": "rejected",
                      "note": sign_note if j in wrong_sign and not worse else why} for j in rejected]
    acc_k = [acc[j] for j in kept]
    findings = [findings[j] for j in kept]
    contributions = [contributions[j] for j in kept]
    say(f"held-out arbiter: {len(findings)} kept, {len(rejected_docs)} rejected ({time.perf_counter() - t0:.1f} s)")
    # 5. where the rest is, grading, status
    cols = list(range(p.n_free)) + [c for i in acc_k for c in col_of[i]]
    D = _design(b, acc_k)  # N·m per unit: the whitener weighs every row once (1/σ_j, its AR filter)
    # what is left where the joints move, the model refitted there: a held joint's rows carry stiction's hold,
    # which changes from rest to rest — no structure along a joint's motion, load or time that a term could take
    Wm = A.Whitener(T, b.W.w, b.W.phi, tab["moving"])
    th_k, *_ = np.linalg.lstsq(Wm(D), Wm(b.y), rcond=None)
    r_final = b.y - D @ th_k
    col_list, pos2 = [], p.n_free
    for i in acc_k:
        col_list.append(list(range(pos2, pos2 + p.lib[i].k)))
        pos2 += p.lib[i].k
    del cols
    variables = A.variables(tab)
    Wv = [lack_of_fit.Variable(v.name, v.unit, v.values, Wm(v.columns), v.centres, v.width, v.gain) for v in variables]
    n_eff = Wm.n_effective - D.shape[1]
    lof = lack_of_fit.test(Wm(r_final), Wm(D), Wv, n_eff, settings.alpha, whiten=Wm,
                           original=(r_final, D, variables))
    where = [{"variable": t.variable, "p_value": t.p_holm, "statistic": t.statistic,
              "region": list(t.region) if isinstance(t.region, tuple) else t.region, "peak_m": t.peak_m,
              "advice": A.advice(t.variable) or checks.advice_for(t.variable)}
             for t in sorted(lof, key=lambda t: t.p_holm) if t.significant]
    effects = [p.lib[i] for i in acc_k]
    grading.grade(findings, effects, contributions, col_list, D, r_final, variables, where, sel.gates, Wm,
                  settings.alpha)
    misfit = arbiter.misspecification(findings, effects, Wm(r_final), Wm(D), Wv, settings.alpha)
    for fd, e in zip(findings, effects):  # a size no joint has: the name is a proxy for something else
        if (beyond := grading.beyond_plausible(fd, e)) is not None:
            fd["confidence"], fd["note"] = "low", beyond
    status, reason = checks.status(len(findings), bool(where), None, worse, misfit, None)
    say(f"status {status} ({time.perf_counter() - t0:.1f} s)")
    return {
        "system": "urdf", "family": "dynamics", "supported": True, "residual_unit": "N·m",
        "n_measurements": int(T), "residual_dim": int(F), "joints": tab["joints"],
        "sigma_m": p.sigma, "sigma_joint_m": b.sigma_joint.tolist(), "alpha": settings.alpha,
        "whitening": {"ar_order": [int(len(ph)) for ph in b.W.phi],
                      "ar_coefficients": [[float(c) for c in ph] for ph in b.W.phi],
                      "note": "rows weighted by 1/σ per joint and whitened by an AR filter per joint fitted on the "
                              "maximal model's residual (feasible GLS): the F tests assume independent rows"},
        "status": status, "status_reason": reason, "noise_floor": None,
        "findings": findings, "rejected_findings": rejected_docs,
        "not_identifiable": [{**n, "reason": _words(n["reason"]), "absorbed_by": _words(n["absorbed_by"])}
                             for n in not_identifiable(sel.gates)],
        "unexplained": bool(where), "unexplained_where": where,
        "lack_of_fit": [{"variable": t.variable, "p_value": t.p_holm, "statistic": t.statistic, "dof": list(t.dof)}
                        for t in lof],
        "holdout_rms_before_m": crossval.rms(before), "holdout_rms_after_m": crossval.rms(final_cv),
        "holdout_rms_with_all_selected_m": crossval.rms(after),
        "holdout_rms_joint_before": crossval.rms(before, axis=0).tolist(),
        "holdout_rms_joint_after": crossval.rms(final_cv, axis=0).tolist(),
        "cross_validation": {"folds": settings.folds, "groups": f"contiguous time blocks, {GUARD_S:g} s guard band",
                             "scored_on": "raw torques at the recorded rate, N·m"},
        "located": locate(tab, before, final_cv),
        "drive_scale": drive_scale(b, sel.gates, findings),
        "candidates": candidates(sel.gates),
        "model": {"base_parameters": int(p.n_free), "choice": fit.choice.label()},
        "timings": {"total_s": time.perf_counter() - t0},
    }
