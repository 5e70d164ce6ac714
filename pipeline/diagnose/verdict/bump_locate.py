"""Where along a variable the structure a lack-of-fit test found is: the narrow bump that explains most of it.

Of single Gaussian bumps (width range/12) at `N_SCAN` centres along the variable, each mapped into the residual
through the variable's gain (and the whitener) and projected against the design, the one that explains most of the
residual per direction it adds — in closed form from the bumps' own rows (`_best_bump`), the choice
`lack_of_fit.scan_basis` + `best_element` make on the projected columns.
"""

from __future__ import annotations

import numpy as np

N_SCAN = 25  # scan centres (as lack_of_fit's)


def locate(v, QA: np.ndarray, res: np.ndarray, n_scan: int = N_SCAN, whiten=None) -> tuple[float, float]:
    """Where along v the structure is: of single narrow bumps (width range/12) at `n_scan`
    centres, each projected against the design (`scan_basis`), the one that explains most of
    the residual; the interval ±1 width around its centre, clipped to v's range."""
    lo, hi = float(v.centres[0]), float(v.centres[-1])
    cs, w = np.linspace(lo, hi, n_scan), (hi - lo) / 12
    b = _best_bump(v, cs, w, QA, res, whiten)
    c = lo if b is None else float(cs[b])
    return float(max(lo, c - w)), float(min(hi, c + w))


def _best_bump(v, cs: np.ndarray, w: float, QA: np.ndarray, res: np.ndarray, whiten=None) -> int | None:
    """The bump (centres cs, width w) along v explaining most of res (⊥ QA) per direction it adds once projected
    ⊥ QA — `scan_basis` and `best_element`'s choice — in closed form on the rows the bumps reach (a joint's own, of
    a whole robot's): with C a bump's columns (one per channel of v's gain), its projected Gram CᵀC − (QAᵀC)ᵀQAᵀC
    and Cᵀres give its gain; a column the design absorbs (left below 10⁻⁶ of its norm) adds no direction."""
    S = cs.size
    C = (v.gain[:, :, None] * np.exp(-0.5 * ((v.values[:, None] - cs[None]) / w) ** 2)[:, None, :]).reshape(
        v.values.size, -1)  # column channel·S + s, as `scan_basis`
    if whiten is not None:
        C = whiten(C)
    rows = np.flatnonzero(np.any(C != 0, axis=1))
    C = C[rows]
    G0 = C.T @ C
    a = QA[rows].T @ C
    G, g = G0 - a.T @ a, C.T @ res[rows]
    best, out = -np.inf, None
    for s in range(S):
        ix = np.arange(s, C.shape[1], S)
        ix = ix[np.diag(G)[ix] > 1e-12 * np.maximum(np.diag(G0)[ix], 1e-300)]
        if not ix.size:
            continue
        n = np.sqrt(np.diag(G)[ix])
        ev, V = np.linalg.eigh(G[np.ix_(ix, ix)] / np.outer(n, n))
        keep = ev > 1e-12 * max(ev[-1], 1e-300)
        gain = float(np.sum((V[:, keep].T @ (g[ix] / n)) ** 2 / ev[keep]))
        if gain / keep.sum() > best:
            best, out = gain / keep.sum(), s
    return out
