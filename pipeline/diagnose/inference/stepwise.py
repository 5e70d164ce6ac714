"""Stepwise selection of candidate terms by grouped F tests under Holm, and look-alikes (sign flips: `sign_flips`).

Linear algebra at the geometric solution (Frisch–Waugh–Lovell): with Q an orthonormal basis
of the free geometric Jacobian columns, a candidate's *projected signature* S⊥ = (I − QQᵀ)S
is what of it the geometry cannot absorb, and the residual r is already ⊥ Q at the optimum.

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

from pipeline.diagnose.inference.gate import RANK_REL
from pipeline.diagnose.inference.projection import orthonormal, project_out


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
    """Each block of A's grouped F test given the others, for a set chosen otherwise (as `forward_select`)."""
    if not A:
        return []
    D = _Design(r, candidates, None, tolerances or [0.0] * len(candidates))
    return _holm_steps(list(A), _conditional(D, list(A), dof_resid), n_family or len(candidates))


LOOK_ALIKE_SHARE = 0.1  # a rival explaining all but this share of a finding's own gain is a look-alike


def look_alikes(r: np.ndarray, candidates: list[np.ndarray], dof_resid: int, A: list[int],
                tolerances: list[float] | None = None, level: float = 0.95,
                share: float = LOOK_ALIKE_SHARE) -> dict[int, list[tuple[int, float]]]:
    """Candidates the data can hardly tell from each accepted block b (r and candidates as `forward_select`
    takes them): Δ = (RSS with c in b's place − RSS of A)/σ̂², σ̂² = RSS of A / its residual dof (χ²-scaled;
    negative when c, with more directions, fits better).  c is b's look-alike when Δ < max(χ²_{k_b}(level),
    `share`·G_b), G_b b's own gain given the others: a name the campaign cannot reject, or one explaining all but
    `share` of what b explains (near-collinear: a small error in a shape could swap them).  [(c, Δ)] per b."""
    if not A:
        return {}
    D = _Design(r, candidates, None, tolerances or [0.0] * len(candidates))
    rss_A, rk = D.given(A)[:2]
    rss_A = max(rss_A, 1e-9 * D.rr)  # a near-singular accepted set can round its RSS to nothing
    s2 = max(rss_A / max(dof_resid - rk, 1), 1e-300)
    out = {}
    for b in A:
        rss, _, _, _, kc, gain = D.tests_given([c for c in A if c != b], dof_resid)
        ok = kc > 0
        ok[A] = False
        delta = np.where(ok, (rss - gain - rss_A) / s2, np.inf)
        bound = max(scipy.stats.chi2.ppf(level, D.k[b]), share * (rss - rss_A) / s2 if share else 0.0)
        near = np.flatnonzero((delta < bound) & ((kc <= D.k[b]) | (share > 0)))
        out[b] = [(int(c), float(delta[c])) for c in near[np.argsort(delta[near], kind="stable")]]
    return out
