"""What a dynamics identification offers the diagnosis: its linear problem at the fitted model.

The "geometry" of a dynamics fit is its base regressor X_b (T samples × F fitted joints rows, the
chosen model's base parameters: rigid body, friction, armature); the residual is the raw measured
torque minus the fitted model's.  The adapter builds, at the identification's choice (cut-off and
terms):

- the diagnosis table (`table`): times, filtered positions, velocities, accelerations of the fitted
  joints, the fitted model's torque with its time derivatives, its rigid-body part (the load), the
  identified model's torque derivatives with respect to the joints' motion — everything the library's terms (`library.friction`, `library.drive`) read;
- the rows' noise model: each joint's rows weighted by 1/σ_j (its noise σ, as in weighted least
  squares), then whitened along time by an autoregressive filter per joint (`Whitener`: a torque
  residual at 100 Hz is far from independent sample to sample, and the grouped F tests of the shared
  inference assume independent rows — feasible generalised least squares), σ_j and the AR coefficients
  fitted on the residual of the maximal model (the base regressor and every candidate), so no candidate can
  inflate the noise it is tested against;
- the shared inference's `screen.Problem` on the whitened rows (sample-major: row t·F + f);
- the lack-of-fit variables: per fitted joint its velocity, position and load |τ_rigid| acting on its
  own rows, and the time since the start acting on every joint's rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.diagnose.inference.projection import orthonormal, project_out, residual_of
from pipeline.diagnose.inference.screen import Problem
from pipeline.diagnose.library import drive, friction
from pipeline.diagnose.verdict.lack_of_fit import Variable, smooth_variable
from pipeline.dynamics import identify as I
from pipeline.dynamics import signals
from pipeline.dynamics.rigid_body import RigidBody, _pin_q, standard_parameters

AR_MAX = 8  # the whitener's largest autoregressive order (chosen per joint by BIC)

ADVICE = {"v_": "excite {j} at more speeds, slow ones and reversals included (structure against its velocity)",
          "load_": "move {j} under different loads (a payload, the arm folded and stretched): structure against load"}


def table(rb: RigidBody, data: I.Data, fit: I.Fit) -> dict:
    """The diagnosis table of the identification `fit` on `data` (module docstring)."""
    qf, v, a = signals.derivatives(data.t, data.q, fit.choice.cutoff_hz)
    P = I.prepare(rb, data, fit.choice)
    mask = np.asarray(data.fit, bool)
    n_rb = 10 * rb.n_joints
    tau_fit = P.Xp @ fit.theta
    tau_rigid = P.Xp[:, :, :n_rb] @ fit.theta[:n_rb]
    t = np.asarray(data.t, float)
    dtau = np.gradient(tau_fit, t, axis=0, edge_order=2)
    dq, dv, M = _rnea_derivatives(rb, qf, v, a, mask, _physical_rigid(rb, fit))
    prismatic = np.array([rb.model.joints[int(b)].shortname().startswith("JointModelP") for b in rb.body_of])[mask]
    joints = [j for j, m in zip(rb.joints, mask) if m]
    moving = P.use
    held = I.held_rows(moving, signals.sample_rate(t))
    level = {n: abs(float(x)) for n, x in zip(fit.names, fit.theta)}
    return {"time_s": t - t[0], "q": qf[:, mask], "v": v[:, mask], "a": a[:, mask], "tau": P.raw,
            "tau_fit": tau_fit, "tau_rigid": tau_rigid, "dtau": dtau,
            "dtau_dq": dq, "dtau_dv": dv,
            "mass_matrix": M,
            "coulomb_width": fit.choice.terms.coulomb_width if "coulomb" in fit.choice.terms.friction else 0.01,
            "joints": joints, "prismatic": prismatic,
            "fitted": moving | held, "moving": moving, "held": held,
            "coulomb_level": np.array([level.get(f"{j}.fc", 0.0) for j in joints]),
            "X": P.Xp[:, :, fit.base.independent], "base_names": [fit.names[i] for i in fit.base.independent]}


def _physical_rigid(rb: RigidBody, fit: I.Fit) -> np.ndarray:
    """Rigid-body parameters π (J·10,) for the torque derivatives: the physically consistent fit's (every body a
    body; a base parameter the trajectory hardly excites held near the URDF's), else the URDF's own."""
    n_rb = 10 * rb.n_joints
    if fit.consistent is not None and np.all(np.isfinite(fit.consistent.theta[:n_rb])):
        return np.asarray(fit.consistent.theta[:n_rb], float)
    return standard_parameters(rb)


def _rnea_derivatives(rb: RigidBody, q: np.ndarray, v: np.ndarray, a: np.ndarray, mask: np.ndarray,
                      pi: np.ndarray):
    """∂τ/∂q, ∂τ/∂q̇ and the mass matrix ∂τ/∂q̈ of the fitted joints' torques with respect to the fitted joints'
    motion, (T, F, F) each, with the identified rigid-body parameters π (J·10,) (Pinocchio's RNEA derivatives;
    they are linear in π and depend on its base combinations only, so any π of the identified base parameters
    gives them)."""
    model = rb.model.copy()
    for k, b in enumerate(rb.body_of):
        model.inertias[int(b)] = pin.Inertia.FromDynamicParameters(np.asarray(pi[10 * k:10 * k + 10], float))
    Q = _pin_q(rb, q)
    V = np.zeros((Q.shape[0], rb.model.nv))
    A = np.zeros_like(V)
    V[:, rb.pin_v], A[:, rb.pin_v] = v, a
    d = model.createData()
    idx = rb.pin_v[mask]
    F = idx.size
    out = [np.empty((Q.shape[0], F, F)) for _ in range(3)]
    for i in range(Q.shape[0]):
        pin.computeRNEADerivatives(model, d, Q[i], V[i], A[i])
        M = np.triu(d.M) + np.triu(d.M, 1).T
        for o, D in zip(out, (d.dtau_dq, d.dtau_dv, M)):
            o[i] = D[np.ix_(idx, idx)]
    return tuple(out)


def library(tab: dict) -> list:
    """The dynamics library: friction and drive terms at every fitted joint."""
    return friction.library(tab) + drive.library(tab)


def signatures(tab: dict, effects: list) -> list[np.ndarray]:
    """Each effect's basis (T, F, k) at the table."""
    return [e.basis(None, None, tab) for e in effects]


class Whitener:
    """Rows (T·F, c) sample-major → the same rows weighted by 1/σ_j and filtered along time per joint
    by e_t − Σ φ_jk e_{t−k} (the first samples by the lags they have).  With `use` (T, F) bool, the rows the
    model fits: the others are set to zero before and after the filter (each run of used rows is filtered as a
    series of its own, from rest).  `n_effective` the count of rows kept."""

    def __init__(self, T: int, weights: np.ndarray, phi: list[np.ndarray], use: np.ndarray | None = None):
        self.T, self.F = T, weights.size
        self.w, self.phi = np.asarray(weights, float), phi
        self.use = None if use is None or np.all(use) else np.asarray(use, bool)
        self.n_effective = T * self.F if self.use is None else int(self.use.sum())

    def __call__(self, A: np.ndarray) -> np.ndarray:
        A = np.asarray(A, float)
        one = A.ndim == 1
        w = self.w[None, :, None] if self.use is None else self.w[None, :, None] * self.use[:, :, None]
        B = (A.reshape(self.T, self.F, -1) * w).transpose(1, 0, 2).copy()  # (F, T, c)
        out = B.copy()
        for f, ph in enumerate(self.phi):  # the FIR filter 1 − Σ φ_k z⁻ᵏ along time, from rest
            for k, c in enumerate(ph, start=1):
                out[f, k:] -= c * B[f, :-k]
        if self.use is not None:
            out *= self.use.T[:, :, None]
        out = out.transpose(1, 0, 2).reshape(self.T * self.F, -1)
        return out[:, 0] if one else out


def ar_fit(e: np.ndarray, p_max: int = AR_MAX) -> np.ndarray:
    """AR coefficients φ (p,) of residual series e (T,), order by BIC (0 … p_max), least squares."""
    e = np.asarray(e, float) - np.mean(e)
    T = e.size
    best = (T * np.log(max(float(e @ e) / T, 1e-300)), np.zeros(0))
    for p in range(1, p_max + 1):
        L = np.stack([e[p - k:T - k] for k in range(1, p + 1)], axis=1)
        coef, *_ = np.linalg.lstsq(L, e[p:], rcond=None)
        res = e[p:] - L @ coef
        bic = (T - p) * np.log(max(float(res @ res) / (T - p), 1e-300)) + p * np.log(T - p)
        if bic < best[0]:
            best = (bic, coef)
    return best[1]


@dataclass
class Built:
    """The adapter's output: table, library, signatures (T, F, k) unwhitened, the whitener, the shared
    inference's `Problem` on whitened rows, the weighted (unwhitened) base design and target."""

    table: dict
    lib: list
    S: list[np.ndarray]
    W: Whitener
    problem: Problem
    X: np.ndarray  # (T·F, r) base design, unweighted, sample-major rows
    y: np.ndarray  # (T·F,) raw torques
    sigma_joint: np.ndarray  # (F,) N·m


def build(rb: RigidBody, data: I.Data, fit: I.Fit) -> Built:
    """Table, library, noise model and the shared inference's problem (module docstring)."""
    tab = table(rb, data, fit)
    T, F = tab["tau"].shape
    X = tab["X"].reshape(T * F, -1)
    y = tab["tau"].reshape(T * F)
    lib = library(tab)
    S = signatures(tab, lib)
    # per-joint weights and AR whitening from the maximal model's residual (the base regressor and every
    # candidate): the noise, not the base model's misfit, which holds whatever the candidates would take
    Smat = np.hstack([s.reshape(T * F, -1) for s in S]) if S else np.zeros((T * F, 0))
    # on the rows the identification fits (a crawling joint's are not: its friction there is stiction's, which the
    # model does not describe and no candidate is tested against); the rows of a joint held at rest are tested too
    # (`fitted`: only they separate its moving offset from its rest level) but carry stiction's hold, not the noise
    use, mov = np.asarray(tab["fitted"], bool), np.asarray(tab.get("moving", tab["fitted"]), bool)
    u = mov.reshape(T * F)
    Dmax = np.hstack([X, Smat])[u]
    emax = np.zeros((T, F))
    emax[mov] = residual_of(Dmax, y[u])
    n = max(int(u.sum()), 1)
    sig = np.sqrt(np.sum(emax**2, axis=0) / np.maximum(mov.sum(axis=0), 1) * n / max(n - Dmax.shape[1], 1))
    w = 1.0 / np.maximum(sig, 1e-12)
    W = Whitener(T, w, [ar_fit(emax[mov[:, f], f] * w[f]) if mov[:, f].sum() > 10 * AR_MAX else np.zeros(0)
                        for f in range(F)], use)  # a joint that hardly moves: its few rows unfiltered
    Jf = W(X)
    Q = orthonormal(Jf)
    r = project_out(W(y)[:, None], Q)[:, 0]
    dof = W.n_effective - Q.shape[1]
    Sw = [W(s.reshape(T * F, -1)) for s in S]
    p = Problem(T, F, list(tab["base_names"]), Jf, r, dof, float(np.sqrt(r @ r / max(dof, 1))), lib, Sw)
    return Built(tab, lib, S, W, p, X, y, sig)


def variables(tab: dict) -> list[Variable]:
    """Lack-of-fit variables on the unwhitened sample-major rows (module docstring)."""
    T, F = tab["tau"].shape
    out: list[Variable] = []
    for f, name in enumerate(tab["joints"]):
        gain = np.zeros((T, F, 1))
        gain[:, f, 0] = 1.0
        gain = gain.reshape(T * F, 1)
        _, vu = friction.units_of(tab, f)
        for key, unit, vals in (("v", vu, tab["v"][:, f]), ("q", vu.split("/")[0], tab["q"][:, f]),
                                ("load", friction.units_of(tab, f)[0], np.abs(tab["tau_rigid"][:, f]))):
            v = smooth_variable(f"{key}_{name}", unit, np.repeat(vals, F), gain)
            if v is not None:
                out.append(v)
    onehot = np.tile(np.eye(F), (T, 1))
    v = smooth_variable("time_since_start_s", "s", np.repeat(tab["time_s"], F), onehot, K=6)
    if v is not None:
        out.append(v)
    return out


def advice(variable: str) -> str | None:
    """What to do about structure located along a dynamics variable."""
    for key, text in ADVICE.items():
        if variable.startswith(key):
            return text.format(j=variable[len(key):])
    if variable == "time_since_start_s":
        return "log the drives' temperature; repeat the excitation cold and warm (friction that changes over time)"
    return None
