"""One BLAS thread for robocal's small dense algebra.

The diagnosis does thousands of products, QRs and eigendecompositions of matrices of a few
hundred rows by tens of columns.  Multi-threaded OpenBLAS gains nothing at these sizes and, on
a machine whose cores are busy, its worker threads spin-wait for a core: the 300-contact
diagnosis took 2.0 s wall (1.3 s CPU) with OpenBLAS's default threads on a loaded 2-core box
and 0.46 s (0.46 s CPU) with one, bit-identical (`benchmarks/bench_diagnose_speed.py
[--default-blas]`; the gap depends on how busy the cores are).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

_controller = None


@contextlib.contextmanager
def one_thread() -> Iterator[None]:
    """Run the block with every loaded BLAS (numpy's and scipy's OpenBLAS) limited to one thread;
    the previous limits are restored on exit."""
    global _controller
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:  # a dependency (pyproject); without it the BLAS defaults stay
        yield
        return
    if _controller is None:
        import scipy.linalg  # noqa: F401  (load scipy's BLAS before the controller looks for libraries)

        _controller = ThreadpoolController()
    with _controller.limit(limits=1, user_api="blas"):
        yield


def single_threaded(fn):
    """`fn` run under `one_thread` (identification's QRs and SVDs of a few hundred columns: with
    OpenBLAS's default threads on a busy 2-core box an SVD of 1200×160 took 0.95 s, with one 0.03 s)."""
    import functools

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with one_thread():
            return fn(*args, **kwargs)

    return wrapper
