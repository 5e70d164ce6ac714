"""Which candidate effects the campaign can see, and which ones the data ask for.

Linear algebra at the geometric solution (Frisch–Waugh–Lovell): with Q an orthonormal basis
of the free geometric Jacobian columns, a candidate's *projected signature* S⊥ = (I − QQᵀ)S
is what of it the geometry cannot absorb, and the residual r is already ⊥ Q at the optimum.

- `gate`: absorbed fraction 1 − ‖S⊥‖²/‖S‖², minimum detectable size along the candidate's
  weakest direction, (z₁₋α/(2m) + z₀.₈)·σ/s_min(S⊥) (+ its immaterial tolerance), and
  confounding with other candidates; a candidate whose detectable size is beyond what is
  physically plausible is `not_identifiable`.
- `forward_select`: grouped F tests, one candidate block at a time, each against the
  geometry and the blocks already accepted; Holm's step-down thresholds α/(m − j).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.special
import scipy.stats

from pipeline.diagnose.effects import Effect

POWER_Z = scipy.stats.norm.ppf(0.8)  # 80 % power
RANK_REL = 1e-6  # a projected column this small relative to its original is gone
CONFOUND = 0.95  # share of a projected signature another candidate explains → confounded


def orthonormal(A: np.ndarray, rel_tol: float = 1e-9) -> np.ndarray:
    """Orthonormal basis (n, r) of the columns of A (column-scaled, rank-revealing QR)."""
    if A.size == 0 or A.shape[1] == 0:
        return np.zeros((A.shape[0], 0))
    norms = np.linalg.norm(A, axis=0)
    keep = norms > 0
    if not keep.any():
        return np.zeros((A.shape[0], 0))
    As = A[:, keep] / norms[keep]
    Q, R, _ = scipy.linalg.qr(As, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    return Q[:, : int(np.sum(d > rel_tol * max(d[0], 1e-300)))]


def project_out(A: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """(I − QQᵀ)A."""
    return A - Q @ (Q.T @ A) if Q.shape[1] else A.copy()


@dataclass
class Gate:
    """Detectability of one candidate in this campaign."""

    effect: Effect
    absorbed_fraction: float  # share of ‖S‖² the geometry absorbs
    min_detectable: float  # along the weakest direction, units of the parameters
    identifiable: bool
    absorbed_by: str
    reason: str
    projected: np.ndarray  # S⊥ against geometry (and confounders when they are what hides it)


def _explained(Sp: np.ndarray, Qo: np.ndarray) -> float:
    """Share of ‖Sp‖² (columns unit-scaled) in span(Qo)."""
    n = np.linalg.norm(Sp, axis=0)
    if not np.any(n > 0) or Qo.shape[1] == 0:
        return 0.0
    U = Sp[:, n > 0] / n[n > 0]
    return float(np.sum((Qo.T @ U) ** 2) / np.sum(U**2))


def absorbing_parameters(S: np.ndarray, Jf: np.ndarray, names: list[str], top: int = 3) -> str:
    """The free geometric parameters that best reproduce signature S (first column), named."""
    if Jf.shape[1] == 0:
        return "nothing"
    norms = np.linalg.norm(Jf, axis=0)
    norms[norms == 0] = 1
    s = S[:, 0] / max(np.linalg.norm(S[:, 0]), 1e-300)
    coef, *_ = np.linalg.lstsq(Jf / norms, s, rcond=None)
    best = np.argsort(-np.abs(coef))[:top]
    return " + ".join(names[b] for b in best if abs(coef[b]) > 1e-3) or "nothing"


def gate(effects: list[Effect], S: list[np.ndarray], Jf: np.ndarray, free_names: list[str], sigma: float,
         alpha: float = 0.01) -> list[Gate]:
    """Detectability of every candidate (module docstring); `S[i]` is effect i's signature (n, k)."""
    Q = orthonormal(Jf)
    m = len(effects)
    z = scipy.stats.norm.ppf(1 - alpha / (2 * m)) + POWER_Z
    proj = [project_out(s, Q) for s in S]
    basis = [orthonormal(p) for p in proj]
    order = np.argsort([e.priority for e in effects], kind="stable")
    gates: list[Gate | None] = [None] * m
    kept: list[int] = []
    for i in order:
        e, s, sp = effects[i], S[i], proj[i]
        tot = float(np.sum(s**2))
        absorbed = 1.0 - float(np.sum(sp**2)) / tot if tot > 0 else 1.0
        absorbed_by = absorbing_parameters(s, Jf, free_names) if tot > 0 else "nothing (no effect on these measurements)"
        hide = sp
        conf_label = ""
        # explicit confounders: the union of all candidates of the named kinds
        group = [j for j in range(m) if effects[j].name in e.confounders]
        if group:
            Qg = orthonormal(np.hstack([proj[j] for j in group]))
            share = _explained(sp, Qg)
            if share > 0.5:  # what the confounders leave is what can be detected
                hide = project_out(sp, Qg)
                conf_label = " + ".join(sorted({effects[j].name for j in group}))
                if share > CONFOUND:
                    hide = np.zeros_like(sp)
        # pairwise: an earlier (simpler) identifiable candidate that reproduces this one
        for j in kept:
            if _explained(sp, basis[j]) > CONFOUND:
                hide = np.zeros_like(sp)
                conf_label = effects[j].label
                break
        if tot == 0 or not np.any(hide):  # absorbed, or confounded beyond CONFOUND
            smin = 0.0
        else:
            sv = np.linalg.svd(hide, compute_uv=False)
            smin = float(sv[-1]) if sv.size == e.k else 0.0
            if smin < RANK_REL * np.sqrt(tot):
                smin = 0.0
        if e.data.get("blocked"):  # the library knows this campaign cannot expose it
            smin = 0.0
            conf_label = e.data.get("absorbed_by", "")
        mds = np.inf if smin == 0 else z * sigma / smin + e.tolerance
        ok = bool(np.isfinite(mds) and mds <= e.plausible)
        if conf_label:
            absorbed_by = f"{absorbed_by} with {conf_label}"
        if ok:
            reason = ""
            kept.append(i)
        elif e.data.get("blocked"):
            reason = e.data["blocked"]
        elif tot == 0:
            reason = "no effect on these measurements"
        elif conf_label:
            reason = f"indistinguishable from {conf_label} in this campaign"
        elif smin == 0:
            reason = f"fully absorbed by the geometry ({absorbed_by})"
        else:
            reason = (f"smallest detectable size {mds:.3g} {e.units[0]} exceeds the plausible {e.plausible:.3g} "
                      f"{e.units[0]} ({absorbed * 100:.1f} % absorbed by the geometry)")
        gates[i] = Gate(e, absorbed, float(mds), ok, absorbed_by, reason, sp)
    return gates  # type: ignore[return-value]


@dataclass
class Step:
    """One accepted forward-selection step."""

    index: int  # into the candidate list
    statistic: float  # grouped F
    dof: tuple[int, int]
    p_value: float  # raw
    p_holm: float  # Holm-adjusted (monotone)
    gain: float  # RSS reduction, m²


def forward_select(r: np.ndarray, candidates: list[np.ndarray], dof_resid: int, alpha: float = 0.01,
                   tolerances: list[float] | None = None, max_terms: int = 8, n_family: int | None = None,
                   base: np.ndarray | None = None) -> list[Step]:
    """Forward selection by grouped F with Holm's step-down thresholds (module docstring).

    `r` (n,) residuals ⊥ the geometry; `candidates` their projected signatures (n, k_c);
    `dof_resid` = n − free geometric parameters; `tolerances` per candidate (single-parameter
    interval nulls: an estimate within ±tol counts as zero); `base` columns already in the model.
    All candidates are projected at once; each step costs one matrix product and a few k×k solves.
    """
    m = len(candidates) if n_family is None else n_family
    if not candidates:
        return []
    tol = tolerances or [0.0] * len(candidates)
    ks = [c.shape[1] for c in candidates]
    edges = np.concatenate([[0], np.cumsum(ks)])
    C = np.hstack(candidates)
    cn = np.linalg.norm(C, axis=0)
    C = C / np.where(cn > 0, cn, 1.0)  # unit columns: gains and ranks do not depend on units
    B = np.zeros((r.size, 0)) if base is None else orthonormal(base)
    res = project_out(r[:, None], B)[:, 0]
    rss = float(res @ res)
    dof = dof_resid - B.shape[1]
    steps: list[Step] = []
    chosen: set[int] = set()
    p_adj_prev = 0.0
    for j in range(min(max_terms, m)):
        R = project_out(C, B)
        G = R.T @ R
        g = R.T @ res
        best = None
        for c in range(len(candidates)):
            if c in chosen:
                continue
            sl = slice(edges[c], edges[c + 1])
            Gc, gc = G[sl, sl], g[sl]
            w, V = np.linalg.eigh(Gc)
            keep = w > RANK_REL
            kc = int(keep.sum())
            if kc == 0 or dof - kc < 1:
                continue
            proj = (V[:, keep].T @ gc) / np.sqrt(w[keep])
            gain = float(proj @ proj)
            if tol[c] > 0 and kc == 1 and ks[c] == 1:
                theta = abs(float(gc[0])) / float(Gc[0, 0]) / cn[edges[c]]  # parameter units
                shrink = max(theta - tol[c], 0.0) / theta if theta > 0 else 0.0
                gain *= shrink**2
            F = (gain / kc) / (max(rss - gain, 1e-300) / (dof - kc))
            p = float(scipy.special.fdtrc(kc, dof - kc, F))
            if best is None or p < best[0] or (p == best[0] and F > best[1]):
                best = (p, F, c, kc, gain)
        if best is None:
            break
        p, F, c, kc, gain = best
        if p > alpha / (m - j):
            break
        p_adj_prev = max(p_adj_prev, min(1.0, p * (m - j)))
        steps.append(Step(c, float(F), (kc, dof - kc), p, p_adj_prev, gain))
        chosen.add(c)
        Qc = orthonormal(R[:, edges[c]:edges[c + 1]], 1e-6)
        B = np.hstack([B, Qc])
        res = project_out(res[:, None], Qc)[:, 0]
        rss = float(res @ res)
        dof -= kc
    return steps
