"""The gate: which candidate terms this campaign can see.

Linear algebra at the geometric solution (Frisch–Waugh–Lovell): with Q an orthonormal basis
of the free geometric Jacobian columns, a candidate's *projected signature* S⊥ = (I − QQᵀ)S
is what of it the geometry cannot absorb, and the residual r is already ⊥ Q at the optimum.

- `gate`: absorbed fraction 1 − ‖S⊥‖²/‖S‖², minimum detectable size along the candidate's
  weakest direction, (z₁₋α/(2m) + z₀.₈)·σ/s_min(S⊥) (+ its immaterial tolerance: what could hide), and
  confounding with other candidates; a candidate whose detectable size is beyond what is
  physically plausible is `not_identifiable`; a twin that no plausible size tells from an earlier candidate too.
  Which candidates are tested is decided with m the library's size (before any is known testable); the sizes
  stated for the tested ones are those of the test the selection runs: its first Holm threshold α/m over the
  m tested, and for a k-parameter term the grouped test's k degrees of freedom (`power_scale`: √λ of the
  noncentral χ²_k reaching 80 % power; 50 % for the detection threshold) — a phase the test does not know
  costs power, and the stated size says so.
- `sigma_given`: the residual σ after the effects accepted so far — the gate's σ once something
  is accepted (the geometry-only σ carries the unmodelled effects and inflates every MDS).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.special
import scipy.stats

from pipeline.diagnose.inference.projection import orthonormal, project_out
from pipeline.diagnose.library.term import Effect

POWER_Z = scipy.stats.norm.ppf(0.8)  # 80 % power
RANK_REL = 1e-6  # a projected column this small relative to its original is gone
CONFOUND = 0.95  # share of a projected signature its named confounders explain → confounded
TWIN = 0.99  # share of a projected signature one earlier candidate explains → a twin no campaign size separates


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
    best_detectable: float = np.inf  # along the candidate's best direction (= min_detectable for one parameter)
    threshold: float = np.inf  # the size whose expected test statistic is the family's critical value (50 % power)


def _unit(Sp: np.ndarray) -> tuple[np.ndarray, float] | None:
    """Sp's non-zero columns unit-scaled, and their total square (None: no such column)."""
    n = np.linalg.norm(Sp, axis=0)
    if not np.any(n > 0):
        return None
    U = Sp[:, n > 0] / n[n > 0]
    return U, np.sum(U**2)


def _share(unit: tuple[np.ndarray, float] | None, Qo: np.ndarray) -> float:
    """`_explained` of a signature already unit-scaled by `_unit`."""
    if unit is None or Qo.shape[1] == 0:
        return 0.0
    U, uu = unit
    return float(np.sum((Qo.T @ U) ** 2) / uu)


def _explained(Sp: np.ndarray, Qo: np.ndarray) -> float:
    """Share of ‖Sp‖² (columns unit-scaled) in span(Qo)."""
    return _share(_unit(Sp), Qo)


def absorbing_parameters(S: np.ndarray, Jf: np.ndarray, names: list[str], top: int = 3,
                         pinv: np.ndarray | None = None) -> str:
    """The free geometric parameters that best reproduce signature S (first column), named; `pinv`: the
    pseudo-inverse of the column-normalised Jf when the caller has it (one per gate, not one per candidate)."""
    if Jf.shape[1] == 0:
        return "nothing"
    s = S[:, 0] / max(np.linalg.norm(S[:, 0]), 1e-300)
    if pinv is not None:
        coef = pinv @ s
    else:
        norms = np.linalg.norm(Jf, axis=0)
        norms[norms == 0] = 1
        coef, *_ = np.linalg.lstsq(Jf / norms, s, rcond=None)
    best = np.argsort(-np.abs(coef))[:top]
    return " + ".join(names[b] for b in best if abs(coef[b]) > 1e-3) or "nothing"


def _gate_parts(effects: list[Effect], S: list[np.ndarray], Jf: np.ndarray, free_names: list[str]) -> dict:
    """What the gate needs that does not depend on σ: projected signatures and their bases, and
    per candidate (total ‖S‖², absorbed fraction, absorbing parameters, confounder-group label,
    smallest singular value of what the geometry and the confounder group leave)."""
    Q = orthonormal(Jf)
    m = len(effects)
    norms = np.linalg.norm(Jf, axis=0)
    pinv = np.linalg.pinv(Jf / np.where(norms > 0, norms, 1.0)) if Jf.shape[1] else None
    proj = [project_out(s, Q) for s in S]
    basis = [orthonormal(p) for p in proj]
    per = []
    for i in range(m):
        e, s, sp = effects[i], S[i], proj[i]
        tot = float(np.sum(s**2))
        absorbed = 1.0 - float(np.sum(sp**2)) / tot if tot > 0 else 1.0
        absorbed_by = absorbing_parameters(s, Jf, free_names, pinv=pinv) if tot > 0 else "nothing (no effect on these measurements)"
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
        smax = 0.0
        if tot == 0 or not np.any(hide):  # absorbed, or confounded beyond CONFOUND
            smin = 0.0
        else:
            sv = np.linalg.svd(hide, compute_uv=False)
            smin = float(sv[-1]) if sv.size == e.k else 0.0
            smax = float(sv[0]) if sv[0] >= RANK_REL * np.sqrt(tot) else 0.0
            if smin < RANK_REL * np.sqrt(tot):
                smin = 0.0
        per.append((tot, absorbed, absorbed_by, conf_label, smin, smax))
    return {"proj": proj, "basis": basis, "per": per, "unit": [_unit(p) for p in proj]}


@lru_cache(maxsize=512)  # a few (k, family size) per diagnosis; the noncentral χ² root costs ~5 ms
def power_scale(k: int, level: float, power: float) -> float:
    """√λ (σ per unit of the projected signature's norm along its weakest direction) at which a test of k
    parameters at `level` reaches `power`: k = 1, the two-sided z test z₁₋level/2 + z_power (normal
    approximation, the other tail ignored); k ≥ 2, the noncentral χ²_k (the grouped F with σ known)."""
    if k <= 1:
        return float(scipy.stats.norm.ppf(1 - level / 2) + scipy.stats.norm.ppf(power))
    crit = scipy.stats.chi2.ppf(1 - level, k)
    return float(np.sqrt(scipy.optimize.brentq(lambda lam: scipy.stats.ncx2.sf(crit, k, lam) - power, 0.0, 1e5)))


def gate(effects: list[Effect], S: list[np.ndarray], Jf: np.ndarray, free_names: list[str], sigma: float,
         alpha: float = 0.01, cache: dict | None = None) -> list[Gate]:
    """Detectability of every candidate (module docstring); `S[i]` is effect i's signature (n, k).
    `cache`: a dict kept between calls with the same (effects, S, Jf) and another σ (the σ-free
    part is computed once)."""
    if cache is not None and "per" in cache:
        parts = cache
    else:
        parts = _gate_parts(effects, S, Jf, free_names)
        if cache is not None:
            cache.update(parts)
    proj, basis = parts["proj"], parts["basis"]
    m = len(effects)
    z = scipy.stats.norm.ppf(1 - alpha / (2 * max(m, 1))) + POWER_Z  # no candidates (a camera on measured poses)
    order = np.argsort([e.priority for e in effects], kind="stable")
    gates: list[Gate | None] = [None] * m
    kept: list[int] = []
    for i in order:
        e, sp = effects[i], proj[i]
        tot, absorbed, absorbed_by, conf_label, smin, smax = parts["per"][i]
        # pairwise: an earlier (simpler) identifiable candidate that reproduces this one (> 99 % of its projected
        # signature: a twin); less alike, both are tested and the data decide — near-collinear, both are reported
        # as look-alikes (`stepwise.look_alikes`), not one by the library's order.  (The forms of one effect may
        # be alike: the held-out error chooses, `forms`.)
        for j in kept:
            if effects[j].family == e.family or smax == 0:
                continue
            if _share(parts["unit"][i], basis[j]) > TWIN:
                smin = smax = 0.0
                conf_label = effects[j].label
                break
        if e.data.get("blocked"):  # the library knows this campaign cannot expose it
            smin = smax = 0.0
            conf_label = e.data.get("absorbed_by", "")
        mds = np.inf if smin == 0 else z * sigma / smin + e.tolerance
        best = np.inf if smax == 0 else z * sigma / smax + e.tolerance  # along its best direction
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
        thr = np.inf if smin == 0 else (z - POWER_Z) * sigma / smin + e.tolerance
        gates[i] = Gate(e, absorbed, float(mds), ok, absorbed_by, reason, sp, float(best), float(thr))
    # the sizes of the tested candidates, stated for the test the selection runs (module docstring)
    m_t = sum(g.identifiable for g in gates)
    for g in gates:
        if not g.identifiable:
            continue
        k, tol = g.effect.k, g.effect.tolerance
        s80 = power_scale(k, alpha / m_t, 0.8)
        s50 = power_scale(k, alpha / m_t, 0.5)  # k = 1: z₁₋α/(2m), the critical value itself
        g.min_detectable = (g.min_detectable - tol) * s80 / z + tol
        g.best_detectable = (g.best_detectable - tol) * s80 / z + tol
        g.threshold = (g.threshold - tol) * s50 / (z - POWER_Z) + tol
    return gates  # type: ignore[return-value]


def sigma_given(r: np.ndarray, J: np.ndarray, blocks: list[np.ndarray], dof_resid: int) -> float:
    """Residual σ (units of r) after the geometry J and the signature `blocks` (n, k_c) of the
    effects accepted so far, dof-corrected (`dof_resid` = n − free geometric parameters).  The
    gate's minimum detectable sizes use it: the geometry-only σ carries every unmodelled effect,
    and two effects at 4× their MDS inflate it enough (×1.8 on the Delta) to gate each other out."""
    Q = orthonormal(J)
    e = project_out(r[:, None], Q)[:, 0]
    if blocks:
        P = orthonormal(project_out(np.hstack(blocks), Q))
        e = project_out(e[:, None], P)[:, 0]
        dof_resid -= P.shape[1]
    return float(np.sqrt(e @ e / max(dof_resid, 1)))
