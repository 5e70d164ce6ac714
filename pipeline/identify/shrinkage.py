"""Shrinkage toward the nominal robot instead of choosing which groups to fix (MAP, scale by GCV).

Every grouped parameter is estimated, each pulled toward its nominal value by its prior 1σ
(`pipeline.accuracy.prior`): the solver minimises

    Σ r(x)²  +  μ² Σ_i ((x_i − x_nominal,i) / σ_prior,i)²

over all parameters, the registration group (instrument frame, tool, targets, sockets, planes)
unpenalised.  μ (m) is the measurement noise divided by the prior's scale; it is chosen from the
data by generalised cross-validation, GCV(μ) = m·RSS / (m − dof)², dof = tr of the linearised hat
matrix, over a grid of μ, each solve warm-started from the previous one (a few cheap fits instead of
one per fold and candidate).  A parameter whose estimate is further from nominal than `PLAUSIBLE`
prior σ is named in `implausible`: the caller warns of it.  The model choice (`shrinkage_fit.shrunk_fit`) takes
the prior's scales by the evidence instead (`pipeline.identify.evidence`: one scale per parameter family, the noise
estimated); `shrink` remains the single-scale GCV choice it is compared with.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from pipeline.identify.plausibility import PLAUSIBLE

GRID = (0.03, 0.1, 0.3, 1.0, 3.0)  # μ as multiples of the registration-only RMS residual (per axis)
EXTEND = 4  # grid steps added beyond each end of GRID (candidates judged on the linearised problem)
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


def shrink(model, data, prior_sigma: np.ndarray, x0: np.ndarray, fixed: tuple[str, ...] = (),
           scale_m: float | None = None, grid=GRID, progress=None, extra: tuple[str, ...] = (),
           extend: bool = True) -> Shrunk:
    """MAP estimate with μ chosen by GCV (module docstring).  `x0`: start (e.g. the registration-only
    fit); `scale_m`: the registration-only RMS residual per axis (default: at x0); `extra`: names
    estimated with the registration (anchored at x0, not pulled toward nominal).

    The ladder of candidates is the grid and, with `extend`, `EXTEND` more of its steps beyond each end (the
    registration-only RMS sets the grid; a robot far off its instrument's frame — planes tens of mm off —
    would otherwise never reach the μ its data support).  Few solves: one at the grid's middle, then GCV of
    every candidate from the problem linearised there (one factorisation each: δ = −(JᵀJ + Λ²)⁻¹(Jᵀr +
    Λ²(x − centre)), dof = tr((JᵀJ + Λ²)⁻¹JᵀJ)), a solve at the least, and again until the least is the
    point solved (at most `ROUNDS`).  Scores of solved points are exact, the others linearised."""
    nominal = np.asarray(model.nominal(), float)
    free, w = _penalty(model, np.asarray(prior_sigma, float), fixed, extra)
    wa = w + _anchor(model, np.asarray(prior_sigma, float), fixed, extra)
    centre = np.where(w > 0, nominal, np.asarray(x0, float))
    idx = np.flatnonzero(free)
    r0 = np.asarray(model.residuals(x0, data), float).ravel()
    m = r0.size
    scale = float(scale_m if scale_m is not None else np.sqrt(np.mean(r0**2)))
    scores: dict[float, float] = {}
    at: dict[float, tuple] = {}

    def gcv(J, r, xi, g):
        """(GCV m², dof) at multiple g, linearised at (J, r, xi = x[idx])."""
        lam = g * scale * wa[idx]
        Ai = np.linalg.pinv(J.T @ J + np.diag(lam**2), rcond=1e-12, hermitian=True)  # unpenalised may be rank-deficient
        rl = r - J @ (Ai @ (J.T @ r + lam**2 * (xi - centre[idx])))
        dof = float(np.trace(Ai @ (J.T @ J)))
        return m * float(rl @ rl) / max(m - dof, 1e-9) ** 2, dof

    def solve(g, x):
        mu = g * scale
        x = map_solve(model, data, x, idx, mu * wa[idx], centre)
        r = np.asarray(model.residuals(x, data), float).ravel()
        J = np.asarray(model.jacobian(x, data), float).reshape(m, -1)[:, idx]
        scores[mu], dof = gcv(J, r, x[idx], g)
        at[g] = (mu, x, dof, J, r)
        if progress is not None:
            progress(f"shrinkage μ = {mu * 1e3:.4g} mm (solve {len(at)}): GCV RMS {np.sqrt(scores[mu]) * 1e3:.4g} mm, "
                     f"{dof:.1f} effective parameters")
        return x

    g_sorted = sorted(grid)
    step = (g_sorted[-1] / g_sorted[0]) ** (1 / (len(grid) - 1)) if len(grid) > 1 else 1.0
    k = EXTEND if extend and len(grid) > 1 else 0
    ladder = [g_sorted[0] / step**i for i in range(k, 0, -1)] + g_sorted + [g_sorted[-1] * step**i for i in range(1, k + 1)]
    g = g_sorted[len(g_sorted) // 2]
    solve(g, np.asarray(x0, float).copy())
    for _ in range(ROUNDS if len(ladder) > 1 else 0):
        _, x, _, J, r = at[g]
        lin = {c: scores[at[c][0]] if c in at else gcv(J, r, x[idx], c)[0] for c in ladder}
        for c, v in lin.items():
            scores.setdefault(c * scale, v)
        nxt = min(lin, key=lin.get)
        if nxt in at:
            g = min(at, key=lambda c: scores[at[c][0]])
            break
        solve(nxt, x)
        g = nxt if scores[nxt * scale] <= scores[at[g][0]] else g
    mu, xb, dof = at[g][:3]
    return Shrunk(xb, mu, dict(sorted(scores.items())), dof, _implausible(model, xb, idx, w, nominal), len(at),
                  multiple=g)


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
    if s.tool:  # the tool point (a ball centre) judged free vs known by the same left-out groups
        doc["tool"] = s.tool
        doc["score_m2_tool_" + ("known" if s.tool == "free" else "free")] = {
            key(m): v for m, v in s.other_tool.items()}
    return doc

