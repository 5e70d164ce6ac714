"""Shrinkage toward the nominal robot instead of choosing which groups to fix: the MAP solve and its parts.

Every grouped parameter is estimated, each pulled toward its nominal value by its prior 1σ
(`pipeline.accuracy.prior`): the solver minimises

    Σ r(x)²  +  μ² Σ_i ((x_i − x_nominal,i) / σ_prior,i)²

over all parameters, the registration group (instrument frame, tool, targets, sockets, planes)
unpenalised (anchored weakly at its registration-only estimate where an instrument frame is fitted).
μ (m) is the measurement noise divided by the prior's scale.  It is chosen from the data elsewhere: by
leaving out whole sessions / placements / sockets (`shrinkage_groups`), else by the evidence, one scale per
parameter family (`evidence`); `shrinkage_fit.shrunk_fit` is the whole choice.  Here: the MAP solve, the
penalty and anchor weights, k-fold held-out residuals in closed form, the plausibility list (a parameter
further from nominal than `PLAUSIBLE` prior σ: the caller warns of it) and the results document.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from pipeline.identify.plausibility import PLAUSIBLE

GRID = (0.03, 0.1, 0.3, 1.0, 3.0)  # μ as multiples of the registration-only RMS residual (per axis)
ROUNDS = 4  # at most this many solves after the first (each at the least linearised GCV)


@dataclass(frozen=True)
class Shrunk:
    x: np.ndarray  # (P,) SI
    mu_m: float  # chosen μ (m)
    gcv: dict[float, float]  # μ → GCV score (m²)
    dof: float  # effective number of parameters at μ
    implausible: list[dict]  # [{name, estimate, nominal, prior_sigma, z}, …]
    fits: int  # solves done
    per_group: dict = field(default_factory=dict)  # μ → {group: held-out RMS m} (choice by left-out groups)
    holdout: np.ndarray | None = None  # (n, residual_dim) held-out residuals at the chosen μ (left-out groups)
    physics: dict = field(default_factory=dict)  # {chosen, candidates: {label: {admissible, score_m2, …}}}
    registration: str = "anchored"  # the registration anchored at its registration-only estimate, or "free"
    other_registration: dict = field(default_factory=dict)  # μ → score (m²) with the registration the other way
    multiple: float = float("nan")  # the chosen μ over the registration-only RMS (GCV route)
    lam: np.ndarray | None = None  # (P,) MAP weights λ_i of the evidence route (else μ × 1/σ_prior)
    scales: dict = field(default_factory=dict)  # family → prior scale of greatest evidence (evidence route)
    log_evidence: float = float("nan")  # ln evidence of the linearised model at the estimate (evidence route)
    tool: str = ""  # the tool point "free" or "known" as the left-out groups chose ("": not judged)
    other_tool: dict = field(default_factory=dict)  # μ → score (m²) with the tool point the other way
    passed_over: list = field(default_factory=list)  # candidates scored better than the chosen one, and why not


def _registration(model, extra: tuple[str, ...] = ()) -> set[str]:
    """Names estimated with the registration (unpenalised, anchored at the registration-stage estimate): the
    registration group and `extra` (the physics terms chosen by `pipeline.identify.physics_choice`)."""
    groups = model.groups() if hasattr(model, "groups") else {}
    return set(groups.get("registration", [])) | set(extra)


def _anchor(model, prior_sigma: np.ndarray, fixed: tuple[str, ...], extra: tuple[str, ...] = ()) -> np.ndarray:
    """1/σ of the registration group's free parameters (0 elsewhere): a weak pull toward the registration-only
    estimate (not toward nominal: an instrument stands anywhere), so an instrument frame the data pin down poorly
    stays near where the nominal robot put it.  All zero for a model whose groups' own points take up any rigid
    motion (``fixes_frame`` False: ball-in-socket, each socket's point unknown and its own): its registration-only
    socket points carry the nominal robot's errors, and a pull toward them pulls the robot back toward nominal
    (panda_1, every 5th row held out: 0.621 mm anchored, 0.556 free)."""
    names = model.parameter_names()
    if not getattr(model, "fixes_frame", True):
        return np.zeros(len(names))
    reg = _registration(model, extra) - set(fixed)
    return np.array([1.0 / max(float(s), 1e-12) if n in reg else 0.0 for n, s in zip(names, prior_sigma)])


def _penalty(model, prior_sigma: np.ndarray, fixed: tuple[str, ...], extra: tuple[str, ...] = ()
             ) -> tuple[np.ndarray, np.ndarray]:
    """(free mask, weight 1/σ per parameter; 0 for the registration group and `extra`)."""
    names = model.parameter_names()
    groups = model.groups() if hasattr(model, "groups") else {}
    reg = _registration(model, extra)
    never = {n for g, v in groups.items() if g.startswith("_") for n in v} | set(fixed)
    free = np.array([n not in never for n in names])
    w = np.array([0.0 if (n in reg) else 1.0 / max(float(s), 1e-12) for n, s in zip(names, prior_sigma)])
    return free, np.where(free, w, 0.0)


def map_solve(model, data, x: np.ndarray, idx: np.ndarray, lam: np.ndarray, nominal: np.ndarray) -> np.ndarray:
    """Minimise Σ r² + Σ (lam·(x − nominal))² over x[idx] from `x` (the others held); returns x."""
    x = np.asarray(x, float).copy()
    m = np.asarray(model.residuals(x, data)).size

    def full(z):
        xx = x.copy()
        xx[idx] = z
        return xx

    def fun(z):
        return np.r_[np.asarray(model.residuals(full(z), data), float).ravel(), lam * (z - nominal[idx])]

    def jac(z):
        J = np.asarray(model.jacobian(full(z), data), float).reshape(m, -1)[:, idx]
        return np.vstack([J, np.diag(lam)])

    sol = least_squares(fun, x[idx], jac=jac, method="trf", x_scale="jac", xtol=1e-10, ftol=1e-10, gtol=1e-10)
    return full(sol.x)


def _implausible(model, x, idx, w, nominal) -> list[dict]:
    names = model.parameter_names()
    return [{"name": names[i], "estimate": float(x[i]), "nominal": float(nominal[i]), "prior_sigma": float(1 / w[i]),
             "z": float((x[i] - nominal[i]) * w[i])} for i in idx if w[i] > 0 and abs(x[i] - nominal[i]) * w[i] > PLAUSIBLE]


def fold_holdout(J: np.ndarray, r: np.ndarray, lam: np.ndarray, folds: list[np.ndarray], kd: int) -> np.ndarray:
    """Held-out residuals (n, kd) of each fold left out of the penalised fit, linearised at its solution:
    the rows T of min ‖r + J δ‖² + ‖Λ(x + δ − centre)‖² refitted without them predict e_T = (I − H_TT)⁻¹ r_T,
    H_TT = J_T (JᵀJ + Λ²)⁻¹ J_Tᵀ (exact for a linear model; one factorisation for every fold).  `J`
    (n·kd, p) the Jacobian of the estimated parameters, `r` (n·kd,) the residuals, `lam` (p,) Λ's diagonal."""
    Ainv = np.linalg.pinv(J.T @ J + np.diag(lam**2), rcond=1e-12, hermitian=True)
    out = np.full((r.size // kd, kd), np.nan)
    for test in folds:
        rows = (np.asarray(test)[:, None] * kd + np.arange(kd)).ravel()
        Jt = J[rows]
        e = np.linalg.lstsq(np.eye(rows.size) - Jt @ Ainv @ Jt.T, r[rows], rcond=None)[0]
        out[test] = e.reshape(len(test), kd)
    return out


def shrinkage_document(s: Shrunk) -> dict:
    """results.json → model_selection of a shrinkage fit (SI; μ = null: registration only chosen)."""
    mu = None if np.isinf(s.mu_m) else s.mu_m
    key = lambda m: "registration only" if np.isinf(m) else f"{m:.6g}"  # noqa: E731
    doc = {"method": "shrinkage toward nominal (MAP), scale chosen by "
                     + ("leaving out whole groups" if s.per_group else "the evidence" if s.scales else "GCV"),
           "mu_m": mu, "effective_parameters": s.dof, "implausible": s.implausible,
           "score_m2": {key(m): v for m, v in s.gcv.items()}}
    if s.scales:  # the evidence route: each family's prior scale (× its stated prior 1σ)
        doc["prior_scale_per_family"] = s.scales
    if s.physics:
        doc["physics_families"] = s.physics
    if s.per_group:
        doc["holdout_per_group_m"] = {key(m): v for m, v in s.per_group.items()}
        doc["registration"] = s.registration  # anchored at its registration-only estimate, or free
        doc["score_m2_registration_" + ("free" if s.registration == "anchored" else "anchored")] = {
            key(m): v for m, v in s.other_registration.items()}
    if s.passed_over:  # scored better than the chosen candidate, not chosen: each with its reason
        doc["passed_over"] = s.passed_over
    if s.tool:  # the tool point (a ball centre) judged free vs known by the same left-out groups
        doc["tool"] = s.tool
        doc["score_m2_tool_" + ("known" if s.tool == "free" else "free")] = {
            key(m): v for m, v in s.other_tool.items()}
    return doc

