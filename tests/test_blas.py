"""`pipeline.blas.one_thread`: one BLAS thread inside, the previous limits restored after."""

from __future__ import annotations

import numpy as np
import pytest


def test_one_thread_limits_every_blas_and_restores_the_limits():
    threadpoolctl = pytest.importorskip("threadpoolctl")
    import scipy.linalg  # noqa: F401  (scipy's own OpenBLAS is loaded too)

    from pipeline.blas import one_thread

    def blas_threads():
        return [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]

    before = blas_threads()
    with one_thread():
        inside = blas_threads()
        a = np.random.default_rng(0).normal(size=(50, 50))
        np.linalg.eigh(a + a.T)
    assert inside and all(n == 1 for n in inside)
    assert blas_threads() == before
