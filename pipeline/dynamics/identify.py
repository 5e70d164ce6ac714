"""The whole dynamics identification: model choice by the held-out arbiter, the fit, the prediction.

`identify(rb, data)` tries each candidate model (low-pass cut-off, friction terms, solver) with
contiguous-block cross-validation on the recording's fitted joints, keeps the one whose held-out torque
RMS is lowest, and refits it on every sample.  `predict(rb, fit, t, q)` gives the torques of any other
recording of the robot without refitting.  Pure: arrays in, dataclasses out (N·m, N for prismatic joints).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from pipeline.dynamics import base as B
from pipeline.dynamics import design, signals, solve
from pipeline.dynamics.crossval import blocks, held_out, rms
from pipeline.dynamics.rigid_body import RigidBody, regressor, standard_parameters


@dataclass(frozen=True)
class Data:
    """One recording: times t (T,) s, positions q (T, J), measured torques tau (T, J) N·m / N, which
    joints' torques are fitted `fit` (J,) bool; `decimation` recorded samples per sample here
    (`signals.decimate`: 1, the recording as read)."""

    t: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    fit: np.ndarray
    decimation: int = 1


@dataclass(frozen=True)
class Choice:
    """One candidate model: the positions' low-pass cut-off (Hz), the per-joint
    terms, the solver (ols | wls | consistent) and, for the consistent solver, its ridge toward the URDF."""

    cutoff_hz: float = 4.0
    terms: design.Terms = design.Terms()
    solver: str = "ols"
    ridge: float = 1e-4

    def label(self) -> str:
        t = self.terms
        parts = [f"{self.cutoff_hz:g} Hz", "+".join(t.friction) or "no friction"]
        if t.armature:
            parts.append("armature")
        if "coulomb" in t.friction:
            parts.append(f"Coulomb width {t.coulomb_width:g}")
        return ", ".join(parts + [self.solver])


@dataclass
class Fit:
    """The identified model: the choice, θ (P,) with names and units, the base set, the solution, the
    training and held-out RMS per fitted joint, the condition number, every candidate's held-out RMS."""

    choice: Choice
    names: list[str]
    units: list[str]
    theta: np.ndarray
    base: B.BaseSet
    solution: solve.Solution
    condition: float
    rms_train: np.ndarray
    rms_cv: np.ndarray
    candidates: list[dict] = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    consistent: solve.Solution | None = None  # the physically consistent fit of the chosen structure (model.urdf)
    rms_cv_consistent: np.ndarray | None = None
    cv_residuals: np.ndarray | None = None  # (T, F) held-out residuals of the chosen model


def structural_base(rb: RigidBody, fit: np.ndarray, terms: design.Terms, seed: int = 0, n: int = 120) -> B.BaseSet:
    """The base set of the model's regressor at random states (positions ±π / ±1 m, velocities and
    accelerations standard normal): the dependencies that hold for every trajectory."""
    rng = np.random.default_rng(seed)
    J = rb.n_joints
    q = rng.uniform(-np.pi, np.pi, (n, J))
    v, a = rng.standard_normal((n, J)), rng.standard_normal((n, J))
    X = design.matrix(regressor(rb, q, v, a), v, a, fit, replace(terms, coulomb_width=0.0))
    return B.base_set(X.reshape(-1, X.shape[2]))


@dataclass
class _Prepared:
    X: np.ndarray  # (T, F, P) the training design: the regressor, rows left out of the fit zeroed
    y: np.ndarray  # (T, F) the training target: the raw torques, the same rows zeroed
    raw: np.ndarray  # (T, F) raw torques (the score)
    Xp: np.ndarray  # (T, F, P) the model's regressor at every sample (predicts the raw torques)
    fit: np.ndarray  # (J,) bool: the fitted joints
    use: np.ndarray  # (T, F) bool: the samples the model fits (`fitted_rows`)


def prepare(rb: RigidBody, data: Data, choice: Choice, Y_cache: dict | None = None) -> _Prepared:
    """Regressor and torques of `data` under `choice` (the rigid-body regressor cached per cut-off).

    The positions are low-passed at the cut-off (velocities and accelerations are their derivatives);
    the torques are fitted raw, as they are scored.  Low-passing the torques without low-passing every
    regressor column the same way biases each column that is not smooth at the cut-off — the Coulomb
    step at each velocity reversal above all (the filtered torque rounds the step, the column keeps it
    sharp); raw torques need no such care (their noise is what least squares averages)."""
    key = choice.cutoff_hz
    if Y_cache is not None and key in Y_cache:
        Y, v, a = Y_cache[key]
    else:
        qf, v, a = signals.derivatives(data.t, data.q, choice.cutoff_hz)
        Y = regressor(rb, qf, v, a)
        if Y_cache is not None:
            Y_cache[key] = (Y, v, a)
    X = design.matrix(Y, v, a, data.fit, choice.terms)
    raw = np.asarray(data.tau, float)[:, data.fit]
    use = fitted_rows(v[:, data.fit], choice.terms)
    w = use.astype(float)
    return _Prepared(X * w[:, :, None], raw * w, raw, X, np.asarray(data.fit, bool), use)


def fitted_rows(v: np.ndarray, terms: design.Terms) -> np.ndarray:
    """Which samples (T, F) of the fitted joints' velocities v (T, F) the model fits: all but a crawling joint's.
    The Coulomb step is undefined where a joint starts, stops or reverses (below `SLOW_WIDTHS` Coulomb widths of
    speed): its torque there is whatever stiction and presliding make it, so those samples of that joint are left
    out of the fit (and still scored)."""
    use = np.ones(np.shape(v), bool)
    if "coulomb" in terms.friction and terms.coulomb_width > 0:
        use[np.abs(v) < SLOW_WIDTHS * terms.coulomb_width] = False
    return use


REST_S = 1.0  # a joint below its crawl speed for this long is held at rest (a reversal passes in a few samples)
REST_EDGE_S = 0.25  # the held run's ends left out: the joint starting or stopping, stiction's presliding


def held_rows(use: np.ndarray, fs: float, trim: bool = True) -> np.ndarray:
    """Which samples (T, F) of the fitted joints a joint is *held at rest*: within runs of samples the model does
    not fit (`fitted_rows` False: below the crawl speed) lasting at least `REST_S`, less `REST_EDGE_S` at either
    end (`trim`; the rows a rest level is measured on — untrimmed, the rows it predicts).  What a held joint's
    torque carries beyond the rigid body is its *rest level*: stiction's hold, anywhere within ± its Coulomb level,
    not the moving offset — a level no candidate models."""
    slow = ~np.asarray(use, bool)
    T, F = slow.shape
    n, edge = int(round(REST_S * fs)), int(round(REST_EDGE_S * fs)) if trim else 0
    # every joint's slow runs at once: their starts and ends in the joint-major flattening, padded by one sample
    pad = np.zeros((F, T + 2), np.int8)
    pad[:, 1:-1] = slow.T
    d = np.diff(pad, axis=1).ravel()  # +1 where a run starts, −1 one past its end; row f at f·(T + 1)
    lo, hi = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    keep = hi - lo >= n
    lo, hi = lo[keep] + edge, hi[keep] - edge
    mark = np.zeros(F * (T + 1) + 1, np.int32)
    np.add.at(mark, lo[hi > lo], 1)
    np.add.at(mark, hi[hi > lo], -1)
    return (np.cumsum(mark)[:-1].reshape(F, T + 1)[:, :T] > 0).T


def coulomb_columns(rb: RigidBody, fit: np.ndarray, terms: design.Terms) -> np.ndarray | None:
    """The θ index (F,) of each fitted joint's Coulomb level f_c, None without Coulomb friction."""
    if "coulomb" not in terms.friction:
        return None
    per = [k for k, _ in terms.per_joint()]
    return 10 * rb.n_joints + np.arange(int(np.sum(fit))) * len(per) + per.index("fc")


def _solve(rb: RigidBody, P: _Prepared, rows: np.ndarray, choice: Choice, base: B.BaseSet,
           decimate: int) -> solve.Solution:
    rows = rows[signals.decimation_rows(rows.size, decimate)]
    X, y = P.X[rows], P.y[rows]
    if choice.solver == "ols":
        return solve.ols(X, y, base)
    if choice.solver == "wls":
        return solve.wls(X, y, base)
    n = 10 * rb.n_joints
    keys = [k.rpartition(".")[2] for k in design.extra_names(list(rb.joints), P.fit, choice.terms)[0]]
    nonneg = np.r_[np.zeros(n, bool), np.isin(keys, ("fv", "fc", "Ia"))]
    prior = np.r_[standard_parameters(rb), np.zeros(X.shape[2] - n)]
    return solve.consistent(X, y, base, rb.n_joints, prior, rb.carried, nonneg, ridge=choice.ridge)


def cross_validate(rb: RigidBody, P: _Prepared, choice: Choice, base: B.BaseSet, folds: int, guard: int,
                   decimate: int, rows: np.ndarray | None = None, held: np.ndarray | None = None,
                   rests: np.ndarray | None = None):
    """(held-out residuals (len(rows), F) on the raw torques, contiguous blocks of `rows` (default: every sample);
    the residuals the choice scores).  With `held` (T, F), the samples a joint is held at rest (`held_rows`,
    trimmed) and `rests` (T, F) (untrimmed), the second are the first with each block's rests taken about what of
    the training blocks' rest level (the mean residual over the joint's held samples) lies beyond ± the joint's
    Coulomb level (a level no candidate models); without, the same residuals."""
    rows = np.arange(P.X.shape[0]) if rows is None else rows
    levels = {}
    fc = coulomb_columns(rb, P.fit, choice.terms)

    def fit_predict(train, test):
        s = _solve(rb, P, rows[train], choice, base, decimate)
        if held is not None and fc is not None:
            tr = rows[train]
            level = np.zeros(held.shape[1])
            for f in range(held.shape[1]):  # each joint's held rows only (a joint at rest all along: most rows)
                at = tr[held[tr, f]]
                if at.size:
                    level[f] = float(np.mean(P.Xp[at, f, :] @ s.theta - P.raw[at, f]))
            levels[int(test[0])] = np.sign(level) * np.maximum(np.abs(level) - np.abs(s.theta[fc]), 0.0)
        return P.Xp[rows[test]] @ s.theta - P.raw[rows[test]]

    r = held_out(fit_predict, rows.size, folds, guard)
    if held is None or not levels:
        return r, r
    adj = r.copy()
    h = (held if rests is None else rests)[rows]
    for b in blocks(rows.size, folds):
        adj[b] -= np.where(h[b], levels[int(b[0])][None, :], 0.0)
    return r, adj


SLOW_WIDTHS = 3.0  # below this many Coulomb widths of speed a joint's sample is not fitted (its friction is stiction's)
COULOMB_WIDTHS = (0.0003, 0.003, 0.01, 0.03)  # rad/s (m/s): from a near-sign step to a smooth transition through zero speed
CUTOFFS_HZ = (2.0, 4.0, 8.0, 16.0)  # the positions' low-pass cut-off: noisy encoders want a low one, clean ones a high one
FAST_CUTOFFS_HZ = (32.0, 64.0)  # tried too where the log's rate is at least ten times the cut-off (a fast drive log)
DEFAULT_CANDIDATES = tuple(
    [Choice(cutoff_hz=c, terms=design.Terms(friction=("viscous", "coulomb", "offset"), armature=True, coulomb_width=w))
     for c in CUTOFFS_HZ for w in COULOMB_WIDTHS]
    + [Choice(cutoff_hz=c, terms=design.Terms(friction=("viscous", "offset"), armature=True)) for c in (4.0, 16.0)])


def candidates_for(data: Data, motors: tuple = (),
                   candidates: tuple[Choice, ...] = DEFAULT_CANDIDATES) -> tuple[Choice, ...]:
    """The model candidates for `data`: `candidates`, with the fast cut-offs its rate allows (at least ten
    samples per period: `FAST_CUTOFFS_HZ` × the Coulomb widths), each carrying the coupled `motors`
    (`design.Terms.motors`)."""
    fs = signals.sample_rate(data.t) if np.size(data.t) > 1 else 0.0
    fast = tuple(Choice(cutoff_hz=c, terms=design.Terms(friction=("viscous", "coulomb", "offset"), armature=True,
                                                         coulomb_width=w))
                 for c in FAST_CUTOFFS_HZ if c * 10 <= fs for w in COULOMB_WIDTHS)
    return tuple(replace(c, terms=replace(c.terms, motors=tuple(motors))) for c in (*candidates, *fast))


def identify(rb: RigidBody, data: Data, candidates: tuple[Choice, ...] = DEFAULT_CANDIDATES,
             solvers: tuple[str, ...] = ("ols", "wls", "consistent"), folds: int = 5, guard_s: float = 0.5,
             decimate: int = 1, progress=None, rows: np.ndarray | None = None) -> Fit:
    """Choose the model by held-out torque RMS (pooled over the fitted joints; a joint held at rest scored about
    what of its rest level lies beyond its Coulomb band, `cross_validate`), then refit it on every sample.
    Structure candidates are compared with OLS; the solvers then on the chosen structure.  `rows` (sample
    indices, default all) are the only samples the choice and the fit may use: the others are filtered
    with the trajectory but never seen, so that an outer test can score them (nested cross-validation);
    `cv_residuals` are then those of `rows`."""
    from pipeline.blas import one_thread

    with one_thread():
        return _identify(rb, data, candidates, solvers, folds, guard_s, decimate, progress or (lambda s: None),
                         rows)


def _rests(P: _Prepared, c: Choice, fs: float) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(held, rests) of `cross_validate` for candidate `c`: (None, None) without Coulomb friction or held joints."""
    if "coulomb" not in c.terms.friction or np.all(P.use):
        return None, None
    held = held_rows(P.use, fs)
    return (held, held_rows(P.use, fs, trim=False)) if held.any() else (None, None)


def _identify(rb, data, candidates, solvers, folds, guard_s, decimate, say, use=None) -> Fit:
    t0 = time.perf_counter()
    fs = signals.sample_rate(data.t)
    guard = int(round(guard_s * fs))
    cache: dict = {}
    bases: dict = {}
    rows = []
    best = None
    for c in candidates:
        P = prepare(rb, data, c, cache)
        bkey = (c.terms.friction, c.terms.armature)
        if bkey not in bases:
            bases[bkey] = structural_base(rb, data.fit, c.terms)
        r, adj = cross_validate(rb, P, replace(c, solver="ols"), bases[bkey], folds, guard, decimate, use,
                                *_rests(P, c, fs))
        score = float(rms(adj))
        rows.append({"choice": replace(c, solver="ols").label(), "holdout_rms": float(rms(r)),
                     "holdout_rms_choice": score, "holdout_rms_joint": rms(r, axis=0).tolist()})
        say(f"{replace(c, solver='ols').label()}: held-out {score:.4f}")
        if best is None or score < best[0]:
            best = (score, replace(c, solver="ols"), r)
    t_struct = time.perf_counter() - t0
    choice = best[1]
    P = prepare(rb, data, choice, cache)
    base = bases[(choice.terms.friction, choice.terms.armature)]
    for s in solvers:
        if s == "ols":
            continue
        c = replace(choice, solver=s)
        try:
            r, adj = cross_validate(rb, P, c, base, folds, guard, decimate, use, *_rests(P, c, fs))
        except ArithmeticError as e:
            rows.append({"choice": c.label(), "error": str(e)})
            continue
        score = float(rms(adj))
        rows.append({"choice": c.label(), "holdout_rms": float(rms(r)), "holdout_rms_choice": score,
                     "holdout_rms_joint": rms(r, axis=0).tolist()})
        say(f"{c.label()}: held-out {score:.4f}")
        if score < best[0]:
            best = (score, c, r)
    score, choice, r = best
    all_rows = np.arange(P.X.shape[0]) if use is None else np.asarray(use)
    sol = _solve(rb, P, all_rows, choice, base, decimate)
    cons = sol if choice.solver == "consistent" else _solve(rb, P, all_rows, replace(choice, solver="consistent"),
                                                            base, decimate)
    cv_cons = next((np.array(c["holdout_rms_joint"]) for c in rows
                    if c["choice"] == replace(choice, solver="consistent").label() and "holdout_rms_joint" in c), None)
    names = rb.parameter_names() + design.extra_names(list(rb.joints), data.fit, choice.terms)[0]
    units = rb.parameter_units() + design.extra_names(list(rb.joints), data.fit, choice.terms)[1]
    Xb = P.Xp[:, :, base.independent]
    fit = Fit(choice=choice, names=names, units=units, theta=sol.theta, base=base, solution=sol,
              condition=float(np.linalg.cond(Xb.reshape(-1, Xb.shape[2]))),
              rms_train=rms(P.Xp[all_rows] @ sol.theta - P.raw[all_rows], axis=0), rms_cv=rms(r, axis=0), candidates=rows,
              timings={"choice_s": t_struct, "total_s": time.perf_counter() - t0}, consistent=cons,
              rms_cv_consistent=cv_cons, cv_residuals=r)
    return fit


def predict(rb: RigidBody, fit: Fit, t: np.ndarray, q: np.ndarray, fitted: np.ndarray) -> np.ndarray:
    """Predicted torques (T, F) of the fitted joints for positions q (T, J) at times t (s), no refit."""
    qf, v, a = signals.derivatives(t, q, fit.choice.cutoff_hz)
    from pipeline.blas import one_thread

    with one_thread():
        X = design.matrix(regressor(rb, qf, v, a), v, a, fitted, fit.choice.terms)
        return X @ fit.theta


def from_document(doc: dict) -> Fit:
    """The predictor a run saved (`pipeline.dynamics.stage`): choice and θ (enough for `predict`)."""
    t = doc["terms"]
    choice = Choice(cutoff_hz=float(doc["cutoff_hz"]), solver=str(doc["solver"]),
                    terms=design.Terms(friction=tuple(t["friction"]), armature=bool(t["armature"]),
                                       coulomb_width=float(t["coulomb_width"]),
                                       motors=tuple((str(n), tuple(float(x) for x in g))
                                                    for n, g in t.get("motors", []))))
    theta = np.asarray(doc["theta"], float)
    empty = B.BaseSet(np.arange(0), np.arange(0), np.zeros((0, 0)))
    sol = solve.Solution(theta, np.zeros(0), np.zeros(0), np.zeros(0), choice.solver)
    return Fit(choice, list(doc["names"]), list(doc.get("units", [])), theta, empty, sol, float("nan"),
               np.zeros(0), np.zeros(0))


def nominal_torques(rb: RigidBody, data: Data, fitted: np.ndarray, cutoff_hz: float = 4.0) -> np.ndarray:
    """The URDF's own rigid-body torques (T, F) of the fitted joints (no friction, no armature)."""
    from pipeline.blas import one_thread

    qf, v, a = signals.derivatives(data.t, data.q, cutoff_hz)
    with one_thread():
        return regressor(rb, qf, v, a)[:, fitted] @ standard_parameters(rb)
