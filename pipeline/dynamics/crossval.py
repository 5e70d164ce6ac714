"""Contiguous-block cross-validation: the held-out arbiter of every dynamics model choice.

Samples of a trajectory are not independent (neighbours share the filter's memory and the same motion),
so a random split would score a model on data it has all but seen.  The T samples are cut into k
contiguous blocks; each block is predicted by a model fitted on the others, less a guard band of
`guard` samples on each side of the held-out block (the low-pass filter's reach).  Scores are on the
*raw* torques at the recorded rate — the figure FIGAROH publishes.
"""

from __future__ import annotations

import numpy as np


def blocks(n: int, k: int) -> list[np.ndarray]:
    """k contiguous blocks of row indices covering range(n)."""
    edges = np.linspace(0, n, k + 1).round().astype(int)
    return [np.arange(edges[i], edges[i + 1]) for i in range(k)]


def train_rows(n: int, held: np.ndarray, guard: int) -> np.ndarray:
    """Rows outside the held-out block and its guard band."""
    keep = np.ones(n, bool)
    keep[max(held[0] - guard, 0):held[-1] + guard + 1] = False
    return np.flatnonzero(keep)


def rms(r: np.ndarray, axis=None) -> np.ndarray | float:
    """Root mean square (NaN-free input)."""
    return np.sqrt(np.mean(np.asarray(r, float) ** 2, axis=axis))


def held_out(fit_predict, n: int, k: int, guard: int) -> np.ndarray:
    """Residuals (n, F) of every row predicted by a model fitted without its block:
    `fit_predict(train_rows, test_rows) -> residuals (len(test_rows), F)`."""
    parts = [(b, fit_predict(train_rows(n, b, guard), b)) for b in blocks(n, k)]
    out = np.empty((n, parts[0][1].shape[1]))
    for b, r in parts:
        out[b] = r
    return out
