"""Which candidate effects the campaign can see, and which ones the data ask for.

Linear algebra at the geometric solution (Frisch–Waugh–Lovell): with Q an orthonormal basis
of the free geometric Jacobian columns, a candidate's *projected signature* S⊥ = (I − QQᵀ)S
is what of it the geometry cannot absorb, and the residual r is already ⊥ Q at the optimum.

- `gate`: absorbed fraction 1 − ‖S⊥‖²/‖S‖², minimum detectable size along the candidate's
  weakest direction, (z₁₋α/(2m) + z₀.₈)·σ/s_min(S⊥) (+ its immaterial tolerance), and
  confounding with other candidates; a candidate whose detectable size is beyond what is
  physically plausible is `not_identifiable`.
- `sigma_given`: the residual σ after the effects accepted so far — the gate's σ once something
  is accepted (the geometry-only σ carries the unmodelled effects and inflates every MDS).
- `forward_select`: stepwise selection by grouped F tests under Holm's step-down thresholds
  α/(m − j), m the number of testable candidates:
  1. greedy forward pass: add the block with the smallest p given the geometry and the blocks
     already accepted while it passes α/(m − j) (j accepted so far; exact ties — blocks
     interchangeable given the accepted set — to the block that alone explains most).  Nothing accepted → stop:
     the refinement never runs on data where the greedy pass finds nothing, so it cannot raise the
     family error of a clean campaign;
  2. backward elimination: test every accepted block given all the others (last-in grouped F);
     while Holm's step-down over these p-values does not reject them all, drop the least
     significant block;
  3. forward additions again (single blocks, same thresholds), then a pair addition: the pair of
     blocks whose joint grouped F given the accepted set is smallest, added when it passes
     α/(m − j) divided by the number of pairs tried (Bonferroni over the search);
  4. repeat 2–3 until the set no longer changes; the blocks reported are those of the final
     backward step, each with its F given the others and Holm-adjusted p.
  A pair whose sum a third candidate imitates (c ≈ a + b after projection) is the case this is
  for: the greedy pass takes c and, given c, neither a nor b alone is significant; the pair {a, b}
  is, and then c is no longer significant given {a, b}.  Conversely, when c alone is the truth and
  lies in span(a, b), {a, b} adds only noise directions and parsimony keeps c.  Everything after
  the set-up is algebra on the K×K Gram matrix of the unit-scaled candidate columns (K = Σk_c):
  fits of any set and the tests of every block or pair against it, no refits.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.optimize
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


def _gate_parts(effects: list[Effect], S: list[np.ndarray], Jf: np.ndarray, free_names: list[str]) -> dict:
    """What the gate needs that does not depend on σ: projected signatures and their bases, and
    per candidate (total ‖S‖², absorbed fraction, absorbing parameters, confounder-group label,
    smallest singular value of what the geometry and the confounder group leave)."""
    Q = orthonormal(Jf)
    m = len(effects)
    proj = [project_out(s, Q) for s in S]
    basis = [orthonormal(p) for p in proj]
    per = []
    for i in range(m):
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
        if tot == 0 or not np.any(hide):  # absorbed, or confounded beyond CONFOUND
            smin = 0.0
        else:
            sv = np.linalg.svd(hide, compute_uv=False)
            smin = float(sv[-1]) if sv.size == e.k else 0.0
            if smin < RANK_REL * np.sqrt(tot):
                smin = 0.0
        per.append((tot, absorbed, absorbed_by, conf_label, smin))
    return {"proj": proj, "basis": basis, "per": per, "unit": [_unit(p) for p in proj]}


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
    z = scipy.stats.norm.ppf(1 - alpha / (2 * m)) + POWER_Z
    order = np.argsort([e.priority for e in effects], kind="stable")
    gates: list[Gate | None] = [None] * m
    kept: list[int] = []
    for i in order:
        e, sp = effects[i], proj[i]
        tot, absorbed, absorbed_by, conf_label, smin = parts["per"][i]
        # pairwise: an earlier (simpler) identifiable candidate that reproduces this one
        for j in kept:
            if _share(parts["unit"][i], basis[j]) > CONFOUND:
                smin = 0.0
                conf_label = effects[j].label
                break
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


@dataclass
class Step:
    """One accepted candidate block and its grouped F test: given every other accepted block
    (after the refinement), or given the blocks accepted before it (greedy pass only)."""

    index: int  # into the candidate list
    statistic: float  # grouped F
    dof: tuple[int, int]
    p_value: float  # raw
    p_holm: float  # Holm-adjusted (step-down, monotone)
    gain: float  # RSS reduction, m² (units of r²)


def _batches(edges: np.ndarray, groups) -> list[tuple[np.ndarray, np.ndarray]]:
    """Groups of blocks by total width L: (positions in `groups`, column indices (P, L))."""
    by: dict[int, tuple[list, list]] = {}
    for i, q in enumerate(groups):
        ix = np.concatenate([np.arange(edges[c], edges[c + 1]) for c in q])
        by.setdefault(ix.size, ([], []))
        by[ix.size][0].append(i)
        by[ix.size][1].append(ix)
    return [(np.array(pos), np.array(rows)) for pos, rows in by.values()]


@functools.lru_cache(maxsize=16)
def _single_batches(k: tuple[int, ...]) -> list:
    """The batches of the single blocks of widths k (every resample of the bootstrap has the same)."""
    return _batches(np.concatenate([[0], np.cumsum(k)]).astype(int), [(c,) for c in range(len(k))])


@functools.lru_cache(maxsize=16)
def _pair_batches(k: tuple[int, ...]) -> tuple[np.ndarray, list]:
    """Every pair of blocks (c < d) of widths k and their batches (the bootstrap reuses them)."""
    nc = len(k)
    pl = np.array([(c, d) for c in range(nc) for d in range(c + 1, nc)], int).reshape(-1, 2)
    return pl, _batches(np.concatenate([[0], np.cumsum(k)]).astype(int), [tuple(q) for q in pl])


class _Design:
    """The candidate blocks as Gram algebra: with C the unit-scaled candidate columns (⊥ the
    geometry and `base`), G = CᵀC, g = Cᵀr, the fit of any set S of blocks and every column with
    S partialled out (Frisch–Waugh–Lovell) are K×K products (K = Σk_c); no n-row work after set-up,
    and the tests of all blocks (or pairs of blocks) against one fit are one batched eigh per width."""

    def __init__(self, r: np.ndarray, candidates: list[np.ndarray], base: np.ndarray | None,
                 tolerances: list[float]):
        self.nc = len(candidates)
        self.k = np.array([c.shape[1] for c in candidates])
        self.edges = np.concatenate([[0], np.cumsum(self.k)]).astype(int)
        self.ix = [np.arange(self.edges[c], self.edges[c + 1]) for c in range(self.nc)]
        C = np.hstack(candidates)
        cn = np.linalg.norm(C, axis=0)
        self.cn = np.where(cn > 0, cn, 1.0)
        C = C / self.cn  # unit columns: gains and ranks do not depend on units
        B = np.zeros((r.size, 0)) if base is None else orthonormal(base)
        if B.shape[1]:
            C, r = project_out(C, B), project_out(r[:, None], B)[:, 0]
        self.nb = B.shape[1]
        self.G, self.g, self.rr = C.T @ C, C.T @ r, float(r @ r)
        self.tol = np.asarray(tolerances, float)
        self.singles = _single_batches(tuple(int(k) for k in self.k))
        self._pairs = None
        self._memo: dict = {}  # the selection revisits the same sets: (set, …) -> results

    def _batches(self, groups: list[tuple[int, ...]]) -> list[tuple[np.ndarray, np.ndarray]]:
        return _batches(self.edges, groups)

    @property
    def pairs(self) -> tuple[np.ndarray, list]:
        if self._pairs is None:
            self._pairs = _pair_batches(tuple(int(k) for k in self.k))
        return self._pairs

    def given(self, S, only: int | None = None) -> tuple[float, int, np.ndarray, np.ndarray]:
        """(RSS, rank) of the fit of blocks S, and (G, g) of all columns (or of block `only`'s)
        with S partialled out (memoised per (S in order, only); read them, do not write)."""
        key = ("given", tuple(S), only)
        if key not in self._memo:
            self._memo[key] = self._given(S, only)
        return self._memo[key]

    def _given(self, S, only: int | None) -> tuple[float, int, np.ndarray, np.ndarray]:
        cols = slice(None) if only is None else self.ix[only]
        if not len(S):
            return self.rr, 0, self.G[np.ix_(cols, cols)] if only is not None else self.G, self.g[cols]
        ix = np.concatenate([self.ix[c] for c in S])
        w, V = np.linalg.eigh(self.G[np.ix_(ix, ix)])
        keep = w > RANK_REL
        Vk = V[:, keep] / np.sqrt(w[keep])  # G_SS⁺ = Vk Vkᵀ on the kept directions
        A = self.G[cols, :][:, ix] @ Vk
        a = self.g[ix] @ Vk
        Gc = self.G[np.ix_(cols, cols)] if only is not None else self.G
        return max(self.rr - float(a @ a), 0.0), int(keep.sum()), Gc - A @ A.T, self.g[cols] - A @ a

    def test(self, c: int, G: np.ndarray, g: np.ndarray, rss: float, dof: int) -> tuple[float, float, int, float]:
        """`tests` of block c alone, (G, g) being its own columns given the fit."""
        w, V = np.linalg.eigh(G)
        keep = w > RANK_REL
        kc = int(keep.sum())
        if kc == 0 or dof - kc < 1:
            return 1.0, 0.0, 0, 0.0
        proj = (V[:, keep].T @ g) / np.sqrt(w[keep])
        gain = float(proj @ proj)
        if self.tol[c] > 0 and kc == 1 and self.k[c] == 1:
            theta = abs(float(g[0])) / float(G[0, 0]) / self.cn[self.edges[c]]  # parameter units
            gain *= (max(theta - self.tol[c], 0.0) / theta if theta > 0 else 0.0) ** 2
        F = (gain / kc) / (max(rss - gain, 1e-300) / (dof - kc))
        return float(scipy.special.fdtrc(kc, dof - kc, F)), float(F), kc, gain

    @staticmethod
    def gains(G: np.ndarray, g: np.ndarray, batches, n: int) -> tuple[np.ndarray, np.ndarray]:
        """RSS reduction and rank of adding each group (of `batches`, n groups) to the fit (G, g)."""
        gains, ranks = np.zeros(n), np.zeros(n, int)
        for pos, I in batches:
            if I.shape[1] == 1:  # one column: g²/G
                d = G[I[:, 0], I[:, 0]]
                keep = d > RANK_REL
                gains[pos] = np.where(keep, g[I[:, 0]] ** 2 / np.where(keep, d, 1.0), 0.0)
                ranks[pos] = keep
                continue
            w, V = np.linalg.eigh(G[I[:, :, None], I[:, None, :]])
            keep = w > RANK_REL
            proj = np.einsum("pij,pi->pj", V, g[I]) / np.sqrt(np.where(keep, w, 1.0))
            gains[pos] = np.sum(np.where(keep, proj**2, 0.0), axis=1)
            ranks[pos] = keep.sum(axis=1)
        return gains, ranks

    def tests_given(self, S: list[int], dof0: int, groups=None):
        """(RSS, rank) of the fit of blocks S and `tests` of every block (or pair) against it,
        with dof0 − rank residual dof; memoised per (S in order, dof0, groups), fresh arrays."""
        key = (tuple(S), dof0, groups)
        if key not in self._memo:
            rss, rk, G, g = self.given(S)
            self._memo[key] = (rss, rk, self.tests(G, g, rss, dof0 - rk, groups))
        rss, rk, out = self._memo[key]
        return (rss, rk, *(a.copy() for a in out))

    def tests(self, G: np.ndarray, g: np.ndarray, rss: float, dof: int, groups=None):
        """Grouped F of every block (or every pair: groups="pairs") against the fit with Gram
        (G, g), RSS `rss` and `dof` residual dof: (p, F, rank, gain) arrays; p = 1 where a group
        adds no direction.  Single-parameter blocks with a tolerance (interval null ±tol): the gain
        is shrunk as if the estimate were moved to the edge of the interval."""
        if groups == "pairs":
            pl, batches = self.pairs
            gain, kc = self.gains(G, g, batches, len(pl))
        else:
            gain, kc = self.gains(G, g, self.singles, self.nc)
            for c in np.flatnonzero((self.tol > 0) & (self.k == 1) & (kc == 1)):
                j = self.edges[c]
                theta = abs(float(g[j])) / float(G[j, j]) / self.cn[j]  # parameter units
                gain[c] *= (max(theta - self.tol[c], 0.0) / theta if theta > 0 else 0.0) ** 2
        d2 = dof - kc
        ok = (kc > 0) & (d2 >= 1)
        F = np.where(ok, (gain / np.maximum(kc, 1)) / (np.maximum(rss - gain, 1e-300) / np.maximum(d2, 1)), 0.0)
        p = np.where(ok, scipy.special.fdtrc(np.maximum(kc, 1), np.maximum(d2, 1), F), 1.0)
        return p, F, kc, gain


def _conditional(D: _Design, A: list[int], dof0: int) -> list[tuple[float, float, int, float, int]]:
    """Each block of A tested given all the others (`dof0` residual dof before A): (p, F, rank,
    gain, residual dof).  With M = G_AA⁻¹ and β = M g_A, block b's gain given the others is β_bᵀ M_bb⁻¹ β_b (one inverse
    for all blocks); the general path (a block with fewer directions than columns) refits."""
    if not A:
        return []
    ix = np.concatenate([D.ix[c] for c in A])
    w, V = np.linalg.eigh(D.G[np.ix_(ix, ix)])
    if w[0] > RANK_REL:
        M = (V / w) @ V.T
        beta = M @ D.g[ix]
        dof = dof0 - ix.size
        rss = max(D.rr - float(D.g[ix] @ beta), 1e-300)
        out, at = [], 0
        for b in A:
            sl = slice(at, at + D.k[b])
            at += D.k[b]
            raw = gain = float(beta[sl] @ np.linalg.solve(M[sl, sl], beta[sl]))
            if D.tol[b] > 0 and D.k[b] == 1:
                theta = abs(float(beta[sl][0])) / D.cn[D.edges[b]]  # parameter units
                gain *= (max(theta - D.tol[b], 0.0) / theta if theta > 0 else 0.0) ** 2
            kc = int(D.k[b])
            F = (gain / kc) / (max(rss + raw - gain, 1e-300) / dof) if dof >= 1 else 0.0
            p = float(scipy.special.fdtrc(kc, dof, F)) if dof >= 1 else 1.0
            out.append((p, float(F), kc, gain, dof))
        return out
    out = []
    for b in A:
        rss, rk, G, g = D.given([c for c in A if c != b], b)
        p, F, kc, gain = D.test(b, G, g, rss, dof0 - rk)
        out.append((p, F, kc, gain, dof0 - rk - kc))
    return out


def forward_select(r: np.ndarray, candidates: list[np.ndarray], dof_resid: int, alpha: float = 0.01,
                   tolerances: list[float] | None = None, max_terms: int = 8, n_family: int | None = None,
                   base: np.ndarray | None = None, refine: bool = True) -> list[Step]:
    """Stepwise selection of candidate blocks by grouped F tests under Holm's step-down
    thresholds α/(m − j) (module docstring): a greedy forward pass, then (`refine`) backward
    elimination and pair additions until nothing changes.

    `r` (n,) residuals ⊥ the geometry; `candidates` their projected signatures (n, k_c);
    `dof_resid` = n − free geometric parameters; `tolerances` per candidate (single-parameter
    interval nulls: an estimate within ±tol counts as zero); `base` columns already in the model;
    `n_family` the Holm family size m (default: the number of candidates).  Everything after the
    set-up is algebra on the K×K Gram matrix of the unit-scaled candidate columns.
    """
    m = len(candidates) if n_family is None else n_family
    if not candidates:
        return []
    nc = len(candidates)
    D = _Design(r, candidates, base, tolerances or [0.0] * nc)
    dof0 = dof_resid - D.nb
    marginal = D.gains(D.G, D.g, D.singles, nc)[0]  # each block's gain on its own (tie-break)

    def forward(A: list[int]) -> list[tuple[int, float, float, int, float, int]]:
        """Greedy additions to A (in place) while the best block passes α/(m − |A|):
        (block, p, F, rank, gain, residual dof) of each."""
        added = []
        while len(A) < min(max_terms, m):
            rss, rk, p, F, kc, gain = D.tests_given(A, dof0)
            p[A] = 2.0
            c = int(np.lexsort((-F, p))[0])  # smallest p; ties (p underflows to 0) by the larger F
            tie = np.flatnonzero((np.abs(F - F[c]) <= 1e-9 * F[c]) & (kc == kc[c]) & (p <= p[c] * (1 + 1e-9)))
            if tie.size > 1:  # interchangeable given A (same fit): the one that alone explains most
                c = int(tie[np.argmax(marginal[tie])])
            if p[c] > alpha / (m - len(A)):
                break
            added.append((c, float(p[c]), float(F[c]), int(kc[c]), float(gain[c]), dof0 - rk - int(kc[c])))
            A.append(c)
        return added

    def conditional(A: list[int]) -> list[tuple[float, float, int, float, int]]:
        return _conditional(D, A, dof0)

    def holm_fails(ps: list[float]) -> bool:
        """Does Holm's step-down (thresholds α/(m − j)) leave any of these p-values unrejected?"""
        return any(p > alpha / (m - j) for j, p in enumerate(sorted(ps)))

    def backward(A: list[int]) -> tuple[list[int], list]:
        """Drop the least significant block (given the others) while Holm does not reject all;
        the remaining blocks and their `conditional` tests."""
        A = list(A)
        while True:
            cond = conditional(A)
            ps = [t[0] for t in cond]
            if not A or not holm_fails(ps):
                return A, cond
            A.pop(int(np.argmax(ps)))

    def add_pair(A: list[int]) -> bool:
        """Add the pair of blocks whose joint grouped F given A is most significant, if it passes
        α/(m − |A|) divided by the number of pairs tried (Bonferroni over the search); in place."""
        if len(A) + 2 > min(max_terms, m):
            return False
        pl = D.pairs[0]
        free = ~np.isin(pl, A).any(axis=1)
        if not free.any():
            return False
        rss, rk, p, F, _, _ = D.tests_given(A, dof0, "pairs")
        p = np.where(free, p, 2.0)
        i = int(np.lexsort((-F, p))[0])
        if p[i] > alpha / (m - len(A)) / int(free.sum()):
            return False
        A.extend(int(c) for c in pl[i])
        return True

    def exchange(A: list[int]) -> bool:
        """Swap one accepted block for a not-accepted one with no more directions when the swap
        fits strictly better (a smaller RSS with no more parameters is better under any penalised
        criterion): given a second effect, the greedy pass can pick a look-alike of the true block
        (the scanner's J3 scale for J2's beside a time offset); in place."""
        rss_A = D.given(A)[0]
        best = None
        for b in A:
            rest = [c for c in A if c != b]
            rss, rk, _, _, kc, gain = D.tests_given(rest, dof0)
            ok = (kc > 0) & (kc <= kc[b])
            ok[A] = False
            new = np.where(ok, rss - gain, np.inf)
            c = int(np.argmin(new))
            if new[c] < rss_A * (1 - 1e-6) and (best is None or new[c] < best[0]):
                best = (float(new[c]), b, c)
        if best is None:
            return False
        A[A.index(best[1])] = best[2]
        return True

    A: list[int] = []
    greedy = forward(A)
    if not refine or not A:
        steps, adj = [], 0.0
        for j, (c, p, F, kc, gain, dof) in enumerate(greedy):
            adj = max(adj, min(1.0, p * (m - j)))
            steps.append(Step(c, F, (kc, dof), p, adj, gain))
        return steps
    seen = set()
    for _ in range(2 * max_terms):  # backward elimination, exchanges, forward additions (single, then pairs)
        A, _ = backward(A)
        for _ in range(2 * max_terms):  # each swap lowers the RSS: no cycles
            if not exchange(A):
                break
        forward(A)
        if frozenset(A) in seen or not add_pair(A):
            break
        seen.add(frozenset(A))
    A, cond = backward(A)
    return _holm_steps(A, cond, m)


def _holm_steps(A: list[int], cond: list, m: int) -> list[Step]:
    """Steps of blocks A from their `_conditional` tests, most significant first, Holm-adjusted
    over a family of m."""
    order = np.argsort([t[0] for t in cond], kind="stable")
    steps, adj = [], 0.0
    for j, i in enumerate(order):
        p, F, kc, gain, dof = cond[i]
        adj = max(adj, min(1.0, p * (m - j)))
        steps.append(Step(A[i], F, (kc, dof), p, adj, gain))
    return steps


def conditional_steps(r: np.ndarray, candidates: list[np.ndarray], dof_resid: int, A: list[int],
                      tolerances: list[float] | None = None, n_family: int | None = None) -> list[Step]:
    """The grouped F test of each block of A given the others (as `forward_select` reports its
    final set), for a set chosen otherwise (`cluster_sign_flip_p` dropped some)."""
    if not A:
        return []
    D = _Design(r, candidates, None, tolerances or [0.0] * len(candidates))
    return _holm_steps(list(A), _conditional(D, list(A), dof_resid), n_family or len(candidates))


def wild_cluster_p(res: np.ndarray, QA: np.ndarray, bases: list[np.ndarray], cluster: np.ndarray,
                   n_boot: int = 2999, seed: int = 0) -> np.ndarray:
    """p-value of each block's grouped F against a design by the restricted wild cluster bootstrap:
    the residual r̂ of the design (orthonormal QA; r̂ ⊥ QA, the null model) with each cluster's rows
    times one random sign (Rademacher), re-projected ⊥ QA; `bases` orthonormal (⊥ QA) columns of
    each block.  Each cluster keeps its own error covariance, whatever it is: no estimate of it
    enters the reference (Cameron, Gelbach & Miller 2008) — valid so long as the clusters are
    independent and their errors symmetric.  A draw's RSS is ‖r̂‖² − ‖QAᵀD_s r̂‖² and a block's
    gain ‖QbᵀD_s r̂‖²; Qᵀ D_s r̂ = C s with C the per-cluster contributions (columns × clusters),
    so every draw is algebra in the number of clusters.  Statistic gain/(RSS − gain) (F up to its
    dof); p = (1 + #{T* ≥ T}) / (n_boot + 1), seeded (reproducible)."""
    ids, inv = np.unique(cluster, return_inverse=True)
    Rh = np.asarray(res, float)[:, None] * (inv[:, None] == np.arange(ids.size)[None, :])  # (N, G)
    signs = np.random.default_rng(seed).choice([-1.0, 1.0], size=(ids.size, n_boot))
    rr = float(np.asarray(res, float) @ np.asarray(res, float))
    rss = rr - np.sum((QA.T @ Rh @ signs) ** 2, axis=0)
    p = np.ones(len(bases))
    for b, Qb in enumerate(bases):
        if Qb.shape[1] == 0:
            continue
        Cb = Qb.T @ Rh
        g_obs = float(np.sum(Cb.sum(axis=1) ** 2))
        t_obs = g_obs / max(rr - g_obs, 1e-300)
        g = np.sum((Cb @ signs) ** 2, axis=0)
        p[b] = (1 + np.count_nonzero(g / np.maximum(rss - g, 1e-300) >= t_obs * (1 - 1e-12))) / (n_boot + 1)
    return p


def look_alikes(r: np.ndarray, candidates: list[np.ndarray], dof_resid: int, A: list[int],
                tolerances: list[float] | None = None, level: float = 0.95) -> dict[int, list[tuple[int, float]]]:
    """Candidates the data can hardly tell from each accepted block: for b in A and every c not in A
    with no more directions, Δ = (RSS with c in b's place − RSS of A)/σ̂² (σ̂² = RSS of A / its residual
    dof; r and the candidates as `forward_select` takes them).  The swap fits worse by Δ (a
    likelihood-ratio distance, χ²-scaled); those with Δ < χ²_{k_b}(level) are returned per block,
    closest first, as [(c, Δ)] — a name the campaign cannot reject beside b's."""
    if not A:
        return {}
    D = _Design(r, candidates, None, tolerances or [0.0] * len(candidates))
    rss_A, rk = D.given(A)[:2]
    s2 = rss_A / max(dof_resid - rk, 1)
    out = {}
    for b in A:
        rss, _, _, _, kc, gain = D.tests_given([c for c in A if c != b], dof_resid)
        ok = (kc > 0) & (kc <= D.k[b])
        ok[A] = False
        delta = np.where(ok, (rss - gain - rss_A) / max(s2, 1e-300), np.inf)
        near = np.flatnonzero(delta < scipy.stats.chi2.ppf(level, D.k[b]))
        out[b] = [(int(c), float(delta[c])) for c in near[np.argsort(delta[near], kind="stable")]]
    return out


def cluster_sign_flip_p(r: np.ndarray, blocks: list[np.ndarray], base: np.ndarray, cluster: np.ndarray,
                        n_draw: int = 9999, seed: int = 0) -> np.ndarray:
    """p-value of each block (N, k_b) given `base` and the other blocks (the last-in grouped F) by
    the restricted wild cluster bootstrap (`wild_cluster_p`): the check on a selection whose F
    tests assume one model of the error within a cluster (`cluster_whitener`)."""
    p = np.ones(len(blocks))
    for b in range(len(blocks)):
        Q0 = orthonormal(np.hstack([base] + [blocks[c] for c in range(len(blocks)) if c != b]))
        r0 = project_out(np.asarray(r, float)[:, None], Q0)[:, 0]
        p[b] = wild_cluster_p(r0, Q0, [orthonormal(project_out(blocks[b], Q0))], cluster, n_draw, seed)[0]
    return p


# ----- pose-clustered inference -------------------------------------------------------------
@dataclass
class Whitener:
    """Block-diagonal W = σ_w·Σ^{-1/2} of a random-effects error model per cluster (pose):
    r_g = Z_g u_g + e_g, u_g ~ (0, Ψ), e_g ~ (0, σ_w² I), Σ_g = σ_w² I + Z_g Ψ Z_gᵀ.

    Applying W to residuals, Jacobians and signatures turns the correlated rows of a pose into
    rows with variance σ_w² that are (to the estimate of Ψ) independent, so the grouped F tests
    and the minimum detectable sizes hold: a pose-level signature (inside span Z_g) is tested
    against the between-pose variance σ_w² + Z Ψ Zᵀ, a within-pose one against σ_w²."""

    blocks: list[tuple[np.ndarray, np.ndarray]]  # (row indices, W_g)
    sigma_within: float  # σ_w, m
    psi: np.ndarray  # (p, p) between-cluster covariance of u, units of Z's columns
    n_clusters: int
    pre: object = None  # a per-measurement noise-shape whitener applied first (or None)
    n_effective: int = 0  # residual dimensions that carry noise (structural zeros excluded)

    def __call__(self, A: np.ndarray) -> np.ndarray:
        A = np.asarray(A, float)
        if self.pre is not None:
            A = self.pre(A)
        out = A.copy()
        for rows, W in self.blocks:
            out[rows] = W @ A[rows]
        return out


@dataclass
class NoiseModel:
    """Within-cluster noise of `noise_components`: variance per source (+ isotropic, last) and
    the number of residual dimensions each cluster's rows really span (`effective_rows`)."""

    variances: np.ndarray
    effective_rows: dict


def noise_components(r: np.ndarray, Z: np.ndarray, cluster: np.ndarray, sources: list[np.ndarray],
                     void_tol: float = 1e-8) -> NoiseModel:
    """Variance components of the within-cluster noise, by moments.  Each measurement's k rows get
    Σ_i = Σ_j s_j N_ij N_ijᵀ + s_iso I (N_j (n, k, c_j) a noise source's map to the residual, e.g. a
    pixel error through ∂P/∂pixel).  Per cluster g, what neither the sources nor the cluster basis
    Z_g reach (the complement of span[blockdiag N_i, Z_g]) can only hold isotropic noise: s_iso is
    its mean square.  When that is nil (a structural zero: the scanner's reconstructed points all
    lie in the laser plane, so the off-plane residuals of a pose's collinear corners are affine
    along the line, i.e. rigid, whatever the parameters) those dimensions carry neither noise nor
    signal and must not count as residual degrees of freedom: `effective_rows[g]` is the rank of
    span[blockdiag N_i, Z_g] then (all rows otherwise).  The source variances s_j are the
    least-squares fit of every entry of e_g e_gᵀ (e_g = P_g r_g, P_g = I − Z_g Z_g⁺) to
    P_g Σ_g P_g (unbiased moments), clipped ≥ 0."""
    r = np.asarray(r, float)
    Z = np.asarray(Z, float)
    n, k = sources[0].shape[:2]
    srcs = [np.asarray(N, float) for N in sources]
    blocks = [np.einsum("nic,njc->nij", N, N) for N in srcs]
    meas = np.arange(n * k) // k
    X, y, eff = [], [], {}
    ss_void, dim_void, ss_all = 0.0, 0, 0.0
    per = []
    for c in np.unique(cluster):
        rows = np.flatnonzero(cluster == c)
        Zg = Z[rows]
        Pg = np.eye(rows.size) - Zg @ np.linalg.pinv(Zg, rcond=1e-9)
        ms, loc = np.unique(meas[rows], return_inverse=True)
        Nb = np.zeros((rows.size, sum(N.shape[2] for N in srcs) * ms.size))
        col = 0
        for N in srcs:
            for a, m in enumerate(ms):
                Nb[loc == a, col:col + N.shape[2]] = N[m]
                col += N.shape[2]
        span = np.hstack([Nb, Zg])
        nrm = np.linalg.norm(span, axis=0)
        span = span[:, nrm > 0] / nrm[nrm > 0]
        U, sv, _ = np.linalg.svd(span, full_matrices=True)
        rk = int(np.sum(sv > void_tol * sv[0])) if sv.size else 0
        Vvoid = U[:, rk:]
        ss_void += float(np.sum((Vvoid.T @ r[rows]) ** 2))
        dim_void += Vvoid.shape[1]
        ss_all += float(r[rows] @ r[rows])
        eff[c] = (rk, rows.size)
        e = Pg @ r[rows]
        cols = []
        for B in blocks:
            Bg = np.zeros((rows.size, rows.size))
            for a, m in enumerate(ms):
                ix = np.flatnonzero(loc == a)
                Bg[np.ix_(ix, ix)] = B[m]
            cols.append((Pg @ Bg @ Pg).ravel())
        per.append((Pg, e))
        X.append(np.stack(cols, axis=1))
        y.append(np.outer(e, e).ravel())
    s_iso = ss_void / dim_void if dim_void else 0.0
    X, y = np.vstack(X), np.concatenate(y)
    y = y - s_iso * np.concatenate([(Pg @ Pg).ravel() for Pg, _ in per])
    sc = np.sqrt(np.sum(X**2, axis=0))
    sc[sc == 0] = 1.0
    sj, *_ = np.linalg.lstsq(X / sc, y, rcond=None)
    sj = np.clip(sj / sc, 0.0, None)
    # void dims hold nothing (relative to the typical source variance): structural zeros
    structural = dim_void > 0 and s_iso <= 1e-10 * ss_all / r.size
    return NoiseModel(np.append(sj, s_iso), {c: (rk if structural else m) for c, (rk, m) in eff.items()})


def _covariance_and_scale(sources: list[np.ndarray], variances: np.ndarray, floor: float) -> tuple[np.ndarray, float]:
    """(Σ (n, k, k) of `measurement_covariance`, the median largest eigenvalue before the floor)."""
    n, k = sources[0].shape[:2]
    C = np.zeros((n, k, k))
    for N, v in zip(sources, variances):
        N = np.asarray(N, float)
        C += v * np.einsum("nic,njc->nij", N, N)
    lam_med = float(np.median(np.linalg.eigvalsh(C + variances[-1] * np.eye(k))[:, -1]))
    C += max(variances[-1], floor * lam_med) * np.eye(k)
    return C, lam_med


def measurement_covariance(sources: list[np.ndarray], variances: np.ndarray, floor: float = 1e-3) -> np.ndarray:
    """Each measurement's noise covariance (n, k, k) m²: Σ_i = Σ_j s_j N_ij N_ijᵀ + s_iso I
    (`noise_components`), the isotropic part at least `floor` × the median largest eigenvalue
    (a guard for directions no source reaches; as in `measurement_whitener`)."""
    return _covariance_and_scale(sources, variances, floor)[0]


def measurement_whitener(sources: list[np.ndarray], variances: np.ndarray, floor: float = 1e-3):
    """Row map (nk, c) → (nk, c) that whitens each measurement's k residual rows by its noise
    covariance Σ_i = Σ_j s_j N_ij N_ijᵀ + s_iso I (`noise_components`).  `floor` (relative to the
    median largest eigenvalue of Σ_i) only guards directions no source reaches against a zero
    variance estimate; the output keeps the residual's units (scaled by √median λ_max)."""
    n, k = sources[0].shape[:2]
    C, lam_med = _covariance_and_scale(sources, variances, floor)
    w, V = np.linalg.eigh(C)
    T = np.einsum("nij,nj,nkj->nik", V, np.sqrt(lam_med) / np.sqrt(w), V)

    def apply(A: np.ndarray) -> np.ndarray:
        A = np.asarray(A, float)
        return np.einsum("nij,njc->nic", T, A.reshape(n, k, -1)).reshape(A.shape)
    return apply


def cluster_whitener(r: np.ndarray, Z: np.ndarray, cluster: np.ndarray, n_fitted: int = 0,
                     pre=None, effective_rows: dict | None = None) -> Whitener | None:
    """Estimate the random-effects model of `Whitener` from residuals r (N,) ⊥ the fitted design,
    with Z (N, p) the random-effect columns of each row (a pose's rigid motion, say) and
    `cluster` (N,) the cluster of each row; None when no cluster holds more rows than Z has
    columns (nothing to separate: every row is its own measurement).

    Moments: per cluster û_g = Z_g⁺ r_g; σ_w² = Σ‖r_g − Z_g û_g‖² / Σ(m_g − rank Z_g); Ψ =
    mean(û_g û_gᵀ) − σ_w² mean((Z_gᵀZ_g)⁺), inflated by the share of the between-cluster degrees
    of freedom the fit (`n_fitted` parameters) used, and clipped to positive semi-definite."""
    r = np.asarray(r, float)
    Z = np.asarray(Z, float)
    if pre is not None:
        r, Z = pre(r[:, None])[:, 0], pre(Z)
    p = Z.shape[1]
    ids = np.unique(cluster)
    members = [np.flatnonzero(cluster == c) for c in ids]
    if not any(m.size > p for m in members):
        return None
    U, V, ss_w, dof_w, dof_b = [], [], 0.0, 0, 0
    pinvs = []
    for c, rows in zip(ids, members):
        Zg = Z[rows]
        Zp = np.linalg.pinv(Zg, rcond=1e-9)
        rk = int(np.linalg.matrix_rank(Zg, tol=1e-9 * max(np.abs(Zg).max(), 1e-300)))
        u = Zp @ r[rows]
        e = r[rows] - Zg @ u
        ss_w += float(e @ e)
        dof_w += (effective_rows[c] if effective_rows is not None else rows.size) - rk
        dof_b += rk
        U.append(u)
        V.append(Zp @ Zp.T)
        pinvs.append(Zp)
    if dof_w < 1:
        return None
    s2 = ss_w / dof_w
    U = np.array(U)
    infl = dof_b / max(dof_b - n_fitted, 1) if n_fitted < dof_b else 1.0
    psi = infl * (U.T @ U) / len(ids) - s2 * np.mean(V, axis=0)
    w, Vec = np.linalg.eigh(0.5 * (psi + psi.T))
    psi = (Vec * np.clip(w, 0, None)) @ Vec.T
    blocks = []
    for rows in members:
        Zg = Z[rows]
        Sg = np.eye(rows.size) + Zg @ psi @ Zg.T / s2
        w, Vec = np.linalg.eigh(Sg)
        blocks.append((rows, (Vec / np.sqrt(np.clip(w, 1e-12, None))) @ Vec.T))
    n_eff = sum(effective_rows.values()) if effective_rows is not None else Z.shape[0]
    return Whitener(blocks, float(np.sqrt(s2)), psi, len(ids), pre, int(n_eff))


# ----- parametric (physical) model of the cluster errors ---------------------------------------
@dataclass
class PhysicalModel:
    """Null model of a clustered residual with a physical cluster error: each measurement's k rows
    carry the independent noise of `sources` (Σ_i = Σ_j s_j N_ij N_ijᵀ + s_iso I, `variances` as
    `noise_components`), and cluster g's rows B_g e_g, e_g ~ N(0, diag θ) with θ constant within
    each column group of `groups` (for the scanner's repeatability: δt and δω of the flange, each
    isotropic, and the encoders' δq).  `draw` simulates residuals from it (for a parametric
    bootstrap; with a finite `scale_dof` the variances' common scale is drawn per draw)."""

    sources: list[np.ndarray]
    variances: np.ndarray
    B: np.ndarray  # (nk, p) how a cluster's error reaches each row
    groups: list[np.ndarray]  # column indices of B sharing one variance
    theta: np.ndarray  # (len(groups),) variance of each group's components
    cluster: np.ndarray  # (nk,) cluster of each row
    scale_dof: float = np.inf  # θ's common scale drawn as χ²_ν/ν per draw (its estimation error); ∞: fixed

    def column_variances(self) -> np.ndarray:
        v = np.zeros(self.B.shape[1])
        for g, t in zip(self.groups, self.theta):
            v[g] = t
        return v

    def draw(self, n_draw: int, seed: int = 0) -> np.ndarray:
        """Residual draws (nk, n_draw) from the model (Gaussian)."""
        rng = np.random.default_rng(seed)
        n, k = self.sources[0].shape[:2]
        out = np.sqrt(self.variances[-1]) * rng.standard_normal((n, k, n_draw))
        for N, v in zip(self.sources, self.variances):
            out += np.sqrt(v) * np.einsum("nkc,ncb->nkb", np.asarray(N, float), rng.standard_normal((n, N.shape[2], n_draw)))
        out = out.reshape(n * k, n_draw)
        ids, inv = np.unique(self.cluster, return_inverse=True)
        e = rng.standard_normal((ids.size, self.B.shape[1], n_draw)) * np.sqrt(self.column_variances())[None, :, None]
        if np.isfinite(self.scale_dof):
            e *= np.sqrt(rng.chisquare(self.scale_dof, n_draw) / self.scale_dof)[None, None, :]
        return out + np.einsum("rp,rpb->rb", self.B, e[inv])


def _cluster_gram(Bj: np.ndarray, cluster: np.ndarray) -> np.ndarray:
    """Block-diagonal Σ_g B_gj B_gjᵀ (nk, nk): the covariance of one group of cluster errors per unit θ."""
    return (Bj @ Bj.T) * (cluster[:, None] == cluster[None, :])


def _block_columns(Bj: np.ndarray, cluster: np.ndarray) -> np.ndarray:
    """(nk, G·c): cluster g's rows of Bj (nk, c) in its own c columns, so that Σ_g B_gj B_gjᵀ = out outᵀ."""
    ids, inv = np.unique(cluster, return_inverse=True)
    c = Bj.shape[1]
    out = np.zeros((Bj.shape[0], ids.size * c))
    cols = inv[:, None] * c + np.arange(c)[None]
    np.put_along_axis(out, cols, Bj, axis=1)
    return out


def physical_components(r: np.ndarray, A: np.ndarray, B: np.ndarray, groups: list[np.ndarray],
                        cluster: np.ndarray, sigma2: float, pre=None, iterations: int = 40,
                        information: bool = False):
    """Variances θ (one per column group of B) of the cluster errors by REML, from residual r of
    design A (both unwhitened; on the `pre`-whitened problem, in which the measurement noise is
    σ_w² = `sigma2` per row, held fixed): V = σ_w² I + Σ_j θ_j V_j, V_j = Σ_g B_gj B_gjᵀ,
    P = V⁻¹ − V⁻¹Q(QᵀV⁻¹Q)⁻¹QᵀV⁻¹ (Q spans A, so the fit's share of the between-cluster dimensions
    is accounted for); score_j = ½(rᵀPV_jPr − tr PV_j), information ½ tr(PV_jPV_k).  Started
    from the moment estimate (E eᵀV_je, e = (I − QQᵀ)r, solved by non-negative least squares),
    then projected Fisher scoring: variances at the bound θ = 0 whose score points below it are
    held there (the step is solved for the others only), and the step is halved until the
    restricted likelihood rises.  The plain step (all variances, clipped) oscillated between two
    states when mechanisms overlap (5 variances, a localised bump in the residual) and could stop
    at θ = 0.  REML rather than moments: when several mechanisms overlap, the moments weight the
    directions only one of them reaches poorly and misplace the variance.  With `information`,
    returns (θ, the REML information matrix ½ tr(PV_jPV_k) at θ)."""
    if pre is not None:
        r, A, B = pre(np.asarray(r, float)[:, None])[:, 0], pre(A), pre(B)
    Q = orthonormal(A)
    e = project_out(r[:, None], Q)[:, 0]
    Bb = [_block_columns(B[:, g], cluster) for g in groups]
    PB = [project_out(b, Q) for b in Bb]
    y = np.array([np.sum((b.T @ e) ** 2) for b in Bb])
    c0 = np.array([sigma2 * np.sum(b * pb) for b, pb in zip(Bb, PB)])
    G = np.array([[np.sum((b.T @ pl) ** 2) for pl in PB] for b in Bb])
    theta, _ = scipy.optimize.nnls(G, y - c0)
    n = r.size

    def fit(th):
        """(restricted log-likelihood up to a constant, P r, [P B_j])."""
        V = sigma2 * np.eye(n) + sum(t * (b @ b.T) for t, b in zip(th, Bb))
        c = scipy.linalg.cho_factor(V)
        ViQ = scipy.linalg.cho_solve(c, Q)
        cq = scipy.linalg.cho_factor(Q.T @ ViQ)
        Vir = scipy.linalg.cho_solve(c, r)
        Pr = Vir - ViQ @ scipy.linalg.cho_solve(cq, ViQ.T @ r)
        ll = -(np.sum(np.log(np.diag(c[0]))) + np.sum(np.log(np.diag(cq[0])))) - 0.5 * float(r @ Pr)
        return ll, Pr, c, ViQ, cq

    ll, Pr, c, ViQ, cq = fit(theta)
    for _ in range(iterations):
        PBb = [scipy.linalg.cho_solve(c, b) - ViQ @ scipy.linalg.cho_solve(cq, ViQ.T @ b) for b in Bb]
        score = np.array([0.5 * (np.sum((b.T @ Pr) ** 2) - np.sum(b * pb)) for b, pb in zip(Bb, PBb)])
        info = np.array([[0.5 * np.sum((bj.T @ pk) ** 2) for pk in PBb] for bj in Bb])
        free = (theta > 0) | (score > 0)
        step = np.zeros_like(theta)
        if free.any():
            step[free] = np.linalg.lstsq(info[np.ix_(free, free)], score[free], rcond=None)[0]
        scale = max(float(np.max(theta)), 1e-300)
        for _half in range(30):
            new = np.clip(theta + step, 0.0, None)
            out = fit(new)
            if out[0] >= ll - 1e-12 * abs(ll):
                break
            step = 0.5 * step
        else:
            break
        done = np.allclose(new, theta, rtol=1e-4, atol=1e-6 * scale)
        theta, (ll, Pr, c, ViQ, cq) = new, out
        if done:
            break
    if not information:
        return theta
    PBb = [scipy.linalg.cho_solve(c, b) - ViQ @ scipy.linalg.cho_solve(cq, ViQ.T @ b) for b in Bb]
    return theta, np.array([[0.5 * np.sum((bj.T @ pk) ** 2) for pk in PBb] for bj in Bb])


def physical_whitener(model: PhysicalModel, sigma2: float, pre=None, n_effective: int = 0) -> Whitener:
    """`Whitener` of a `PhysicalModel`: per cluster Σ_g = σ_w² I + B_g diag θ B_gᵀ on the `pre`-whitened
    rows (each cluster's own covariance, from the physical map B_g — not one Ψ for all clusters)."""
    B = model.B if pre is None else pre(model.B)
    cv = model.column_variances()
    blocks = []
    ids = np.unique(model.cluster)
    for c in ids:
        rows = np.flatnonzero(model.cluster == c)
        Bg = B[rows]
        Sg = np.eye(rows.size) + (Bg * cv) @ Bg.T / sigma2
        w, Vec = np.linalg.eigh(Sg)
        blocks.append((rows, (Vec / np.sqrt(np.clip(w, 1e-12, None))) @ Vec.T))
    return Whitener(blocks, float(np.sqrt(sigma2)), np.diag(cv), ids.size, pre, int(n_effective))
