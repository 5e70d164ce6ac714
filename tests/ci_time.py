"""The suite's time on CI: how `make test` spreads the tests over the machine's cores (pytest-xdist).

`make test` runs ``pytest -n 2 --dist loadgroup``.  Each test file is one unit of work (its module
fixtures are built once, on the worker that runs it); a file or test marked
``pytest.mark.xdist_group("NAME")`` joins the unit NAME instead (tests that must never run at the same
time as each other, whichever file they are in).  Each worker runs BLAS on one thread: two workers on
two cores, each with OpenBLAS's default threads, would make four threads spin-wait for two cores.
"""

from __future__ import annotations

import os

import pytest

WORKER = os.environ.get("PYTEST_XDIST_WORKER")  # "gw0", "gw1", … in an xdist worker; None otherwise
ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}

if WORKER:  # before numpy loads its BLAS here, and inherited by every robocal the tests start
    for _k, _v in ONE_THREAD.items():
        os.environ.setdefault(_k, _v)


def _group(item: pytest.Item) -> str | None:
    marks = list(item.iter_markers("xdist_group"))
    if not marks:
        return None
    m = marks[0]
    return str(m.args[0] if m.args else m.kwargs.get("name", "default"))


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook reads the groups
def pytest_collection_modifyitems(config, items):
    """Every test not in a named group is grouped with its file."""
    for item in items:
        if _group(item) is None:
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::", 1)[0]))
