"""The candidate blocks of a selection as Gram algebra (what `stepwise` works on).

With C the unit-scaled candidate columns (⊥ the geometry and any `base`), G = CᵀC, g = Cᵀr and rr = rᵀr are all
a selection needs: the fit of any set of blocks, every other column with that set partialled out
(Frisch–Waugh–Lovell) and the grouped F of every block or pair against it are K×K products (K = Σk_c), no
n-row work after the set-up.  `Design` builds them from the columns, or `Design.of_gram` takes (G, g, rr) of the
projected columns as given — a bootstrap resample's, summed from per-group Gram matrices
(`resampling.bootstrap_frequency`) without forming its rows.
"""

from __future__ import annotations

import functools

import numpy as np
import scipy.special

from pipeline.diagnose.inference.gate import RANK_REL
from pipeline.diagnose.inference.projection import orthonormal, project_out

EXACT_FIT = 1e-9  # a fit leaving less than this share of rᵀr explains the residual exactly: no noise is left to test against



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


class Design:
    """The candidate blocks as Gram algebra: with C the unit-scaled candidate columns (⊥ the
    geometry and `base`), G = CᵀC, g = Cᵀr, the fit of any set S of blocks and every column with
    S partialled out (Frisch–Waugh–Lovell) are K×K products (K = Σk_c); no n-row work after set-up,
    and the tests of all blocks (or pairs of blocks) against one fit are one batched eigh per width."""

    def __init__(self, r: np.ndarray, candidates: list[np.ndarray], base: np.ndarray | None,
                 tolerances: list[float]):
        C = np.hstack(candidates)
        cn = np.linalg.norm(C, axis=0)
        cn = np.where(cn > 0, cn, 1.0)
        C = C / cn  # unit columns: gains and ranks do not depend on units
        B = np.zeros((r.size, 0)) if base is None else orthonormal(base)
        if B.shape[1]:
            C, r = project_out(C, B), project_out(r[:, None], B)[:, 0]
        self._setup([c.shape[1] for c in candidates], cn, C.T @ C, C.T @ r, float(r @ r), B.shape[1], tolerances)

    @classmethod
    def of_gram(cls, G: np.ndarray, g: np.ndarray, rr: float, widths: list[int], tolerances: list[float]) -> Design:
        """The design of candidate columns C (blocks of `widths`) and residual r, ⊥ the geometry already, from
        G = CᵀC, g = Cᵀr, rr = rᵀr alone (the same as `Design(r, blocks of C, None, tolerances)`)."""
        cn = np.sqrt(np.clip(np.diag(G), 0.0, None))
        cn = np.where(cn > 0, cn, 1.0)
        self = cls.__new__(cls)
        self._setup(widths, cn, G / np.outer(cn, cn), g / cn, float(rr), 0, tolerances)
        return self

    def _setup(self, widths, cn, G, g, rr, nb, tolerances) -> None:
        self.nc = len(widths)
        self.k = np.asarray(widths, int)
        self.edges = np.concatenate([[0], np.cumsum(self.k)]).astype(int)
        self.ix = [np.arange(self.edges[c], self.edges[c + 1]) for c in range(self.nc)]
        self.cn, self.nb = cn, nb
        self.G, self.g, self.rr = G, g, rr
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
        if rss - gain <= EXACT_FIT * self.rr:  # an exact fit: a structural identity, not evidence (`tests`)
            return 1.0, 0.0, kc, gain
        F = (gain / kc) / ((rss - gain) / (dof - kc))
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
        is shrunk as if the estimate were moved to the edge of the interval.  A group whose fit leaves less than
        `EXACT_FIT` of rᵀr is not evidence either (p = 1, F = 0): noise cannot lie in the span of a few columns, so
        the residual does by an identity of the model — the touch model's, say, whose every length scales with the
        jig's face coordinates (the residual is that common scale's derivative): given every face's offset and the
        geometry the fit is exact, with offsets of minus the drawing's coordinates."""
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
        ok = (kc > 0) & (d2 >= 1) & (rss - gain > EXACT_FIT * self.rr)
        F = np.where(ok, (gain / np.maximum(kc, 1)) / (np.maximum(rss - gain, 1e-300) / np.maximum(d2, 1)), 0.0)
        p = np.where(ok, scipy.special.fdtrc(np.maximum(kc, 1), np.maximum(d2, 1), F), 1.0)
        return p, F, kc, gain
