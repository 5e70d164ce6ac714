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

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.special
import scipy.stats

from pipeline.diagnose.inference.candidate_gram import EXACT_FIT
from pipeline.diagnose.inference.candidate_gram import Design as _Design
from pipeline.diagnose.inference.gate import RANK_REL


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
        rss = D.rr - float(D.g[ix] @ beta)
        exact = rss <= EXACT_FIT * D.rr  # A fits the residual exactly: no test rests on it (`Design.tests`)
        out, at = [], 0
        for b in A:
            sl = slice(at, at + D.k[b])
            at += D.k[b]
            raw = gain = float(beta[sl] @ np.linalg.solve(M[sl, sl], beta[sl]))
            if D.tol[b] > 0 and D.k[b] == 1:
                theta = abs(float(beta[sl][0])) / D.cn[D.edges[b]]  # parameter units
                gain *= (max(theta - D.tol[b], 0.0) / theta if theta > 0 else 0.0) ** 2
            kc = int(D.k[b])
            ok = dof >= 1 and not exact
            F = (gain / kc) / ((rss + raw - gain) / dof) if ok else 0.0
            p = float(scipy.special.fdtrc(kc, dof, F)) if ok else 1.0
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
    if not candidates:
        return []
    D = _Design(r, candidates, base, tolerances or [0.0] * len(candidates))
    return select_design(D, dof_resid, alpha, max_terms, n_family, refine)


def select_design(D: _Design, dof_resid: int, alpha: float = 0.01, max_terms: int = 8, n_family: int | None = None,
                  refine: bool = True) -> list[Step]:
    """`forward_select` on candidates given as their Gram algebra (`candidate_gram.Design`)."""
    nc = D.nc
    m = nc if n_family is None else n_family
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
            ok = (kc > 0) & (kc <= kc[b]) & (rss - gain > EXACT_FIT * D.rr)  # never to an exact fit (`Design.tests`)
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
    rss_A = max(rss_A, EXACT_FIT * D.rr)  # a near-singular accepted set can round its RSS to nothing
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
