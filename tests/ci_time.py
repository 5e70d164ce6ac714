"""The suite's time on CI: how the tests share the machine's cores, and what each test file costs.

`make test` runs ``pytest -n 2 --dist loadfile --no-loadscope-reorder`` (pytest-xdist: two worker
processes, one per core of the CI machine).

* **One unit of work per test file**: a file's tests run on one worker, one after the other, so its
  module fixtures are built once.  A file that says ``pytestmark = pytest.mark.xdist_group("NAME")``
  joins the unit NAME instead (files whose tests must never run at the same time as each other).
  Session fixtures are built once per worker that asks for one; the files using one of the costly
  ones (`SHARED`) form one unit, so it is built once.
* **Heaviest units first**: units are handed to the workers in order of their recorded CPU cost
  (``tests/ci_costs.json``), so that no long file starts last while the other worker sits idle.
* **BLAS on one thread per worker** (and in every `robocal` the tests start): two workers with
  OpenBLAS's default threads would make four threads spin-wait for two cores.
* **Each file's CPU time** (user + sys, of the test process and of every process it started and
  waited for) is summed and printed at the end, heaviest first, with the suite's total.  A file over
  its allowance (``max(ALLOWANCE_S, HEADROOM × its recorded cost)``) is named in a warning.  With
  ``ROBOCAL_CPU_GATE=1`` (a developer's check; CI never sets it, for CPU time depends on the machine's
  load and speed lives in ``benchmarks/``), a file over ``FAIL_FACTOR`` × its allowance fails the run
  where its cost is known: a
  file with a recorded cost, or a new file (not in ``tests/ci_costs.json``: its budget is
  ALLOWANCE_S).  A file listed with no cost (``null``: not measured yet) is only warned of.  To
  stay within: bound its sizes, share its fixtures, move its sweep to ``benchmarks/``; a file that
  must cost more records its cost (``pytest --ci-costs-write``, which rewrites
  ``tests/ci_costs.json`` for the files that ran).
"""

from __future__ import annotations

import json
import os
import re
import resource
from collections import defaultdict
from pathlib import Path

import pytest

__all__ = ["pytest_addoption", "pytest_collection_finish", "pytest_collection_modifyitems", "pytest_configure",
           "pytest_runtest_makereport", "pytest_sessionfinish", "pytest_terminal_summary",
           "pytest_xdist_make_scheduler"]  # the hooks tests/conftest.py takes

WORKER = os.environ.get("PYTEST_XDIST_WORKER")  # "gw0", "gw1", … in an xdist worker; None otherwise
ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
ROOT = Path(__file__).resolve().parents[1]
COSTS = Path(__file__).with_name("ci_costs.json")  # test file (as in a node id) → CPU s, measured
ALLOWANCE_S = 30.0  # CPU s a test file may cost without a recorded cost (a new file's budget)
HEADROOM = 1.5  # a file's allowance over its recorded cost (CPU time varies with the machine's load)
FAIL_FACTOR = 3.0  # with ROBOCAL_CPU_GATE=1, a file of known cost over this many times its allowance fails the run
SHOWN = 20  # files listed in the summary
# Session fixtures too costly to build on both workers: the files whose tests use one form one unit.
SHARED = ("tiago_frozen_protocol",)

if WORKER:  # before numpy loads its BLAS here, and inherited by every robocal the tests start
    for _k, _v in ONE_THREAD.items():
        os.environ.setdefault(_k, _v)


def recorded_costs() -> dict[str, float | None]:
    """The recorded CPU cost (s) of each test file, None for a file listed but not measured yet ({}
    where the table is absent or damaged)."""
    try:
        return {str(k): None if v is None else float(v) for k, v in json.loads(COSTS.read_text()).items()}
    except (OSError, ValueError, AttributeError, TypeError):
        return {}


def allowance(file: str, costs: dict[str, float | None]) -> float:
    """CPU seconds `file` may cost before the summary warns of it."""
    return max(ALLOWANCE_S, HEADROOM * (costs.get(file) or 0.0))


def _file(nodeid: str) -> str:
    return nodeid.split("::", 1)[0]


_GROUP = re.compile(r"""xdist_group\(\s*(?:name\s*=\s*)?["']([^"']+)["']""")
_units: dict[str, str] = {}


def unit_of_file(file: str) -> str:
    """The unit of work of the test file `file` (a path as in a node id, relative to the repository):
    the NAME of the first ``xdist_group("NAME")`` its text names, else the first costly session
    fixture of SHARED it names, else the file itself.  Read from the file's text, so that the xdist
    controller (which collects no test) and the workers agree."""
    if file not in _units:
        try:
            text = (ROOT / file).read_text()
        except OSError:
            text = ""
        m = _GROUP.search(text)
        shared = [f for f in SHARED if f in text]
        _units[file] = m.group(1) if m else shared[0] if shared else file
    return _units[file]


def pytest_addoption(parser):
    parser.addoption("--ci-costs-write", action="store_true", default=False,
                     help="Record the CPU time of each test file that ran in tests/ci_costs.json "
                     "(their allowance and their order on the xdist workers).")


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """With ``--dist loadfile``: xdist's scope scheduler, its scopes being `unit_of_file` (xdist's own
    ``loadgroup`` relies on rewriting node ids, which pytest ≥ 9.2 no longer honours)."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class FileUnits(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return unit_of_file(_file(nodeid))

    return FileUnits(config, log)


def pytest_collection_modifyitems(config, items):
    """The units in order of recorded cost, heaviest first (a file not recorded: ALLOWANCE_S; among
    equal costs, the unit of more tests first, as xdist orders them), each unit's tests in their own
    order (under xdist with ``--no-loadscope-reorder``: the order in which the units are handed to the
    workers)."""
    costs = recorded_costs()
    unit = {id(i): unit_of_file(_file(i.nodeid)) for i in items}
    cost: dict[str, float] = defaultdict(float)
    for f in {_file(i.nodeid) for i in items}:
        cost[unit_of_file(f)] += costs.get(f) or ALLOWANCE_S
    size: dict[str, int] = defaultdict(int)
    first: dict[str, int] = {}
    for n, item in enumerate(items):
        size[unit[id(item)]] += 1
        first.setdefault(unit[id(item)], n)
    items.sort(key=lambda i: (-cost[unit[id(i)]], -size[unit[id(i)]], first[unit[id(i)]]))


def _cpu() -> float:
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime


def pytest_collection_finish(session):
    """The CPU clock's start for the first test (its setup counts; the collection does not)."""
    session._ci_cpu_last = _cpu()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Each phase's report carries the CPU time spent since the previous phase's (setup: since the
    previous test's teardown; module fixtures count where they are built and torn down)."""
    outcome = yield
    now = _cpu()
    last = getattr(item.session, "_ci_cpu_last", None)
    item.session._ci_cpu_last = now
    if last is not None:
        outcome.get_result().user_properties.append(("ci_cpu_s", now - last))


class _Tally:
    """CPU per test file, summed from the reports (in the controller, under xdist or not)."""

    def __init__(self):
        self.cpu: dict[str, float] = defaultdict(float)

    def pytest_runtest_logreport(self, report):
        for k, v in getattr(report, "user_properties", ()):
            if k == "ci_cpu_s":
                self.cpu[_file(report.nodeid)] += float(v)


def pytest_configure(config):
    if not WORKER:
        config.pluginmanager.register(_Tally(), "ci_time_tally")


def _over(tally, costs) -> tuple[dict[str, float], dict[str, float]]:
    """(files over their allowance, files over FAIL_FACTOR × their allowance): file → CPU s."""
    over = {f: s for f, s in tally.cpu.items() if s > allowance(f, costs)}
    return over, {f: s for f, s in over.items()
                  if s > FAIL_FACTOR * allowance(f, costs) and (f not in costs or costs[f] is not None)}


def pytest_sessionfinish(session, exitstatus):
    """With ROBOCAL_CPU_GATE=1 (a developer's check, never set by CI: CPU time depends on the machine's
    load, and speed lives in benchmarks), a file of known cost over FAIL_FACTOR × its allowance fails the
    run (the summary says which)."""
    tally = session.config.pluginmanager.get_plugin("ci_time_tally")
    if tally is None or os.environ.get("ROBOCAL_CPU_GATE") != "1" or session.config.getoption("ci_costs_write"):
        return
    if _over(tally, recorded_costs())[1] and session.exitstatus == 0:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    tally = config.pluginmanager.get_plugin("ci_time_tally")
    if tally is None or not tally.cpu:
        return
    costs, tr = recorded_costs(), terminalreporter
    tr.write_sep("-", f"CPU time by test file (user+sys, with the processes it started): "
                 f"{sum(tally.cpu.values()):.0f} s in all")
    for f, s in sorted(tally.cpu.items(), key=lambda kv: -kv[1])[:SHOWN]:
        tr.write_line(f"{s:8.1f} s  {f}  (allowance {allowance(f, costs):.0f} s)")
    over, failing = _over(tally, costs)
    for f, s in sorted(over.items(), key=lambda kv: -kv[1]):
        tr.write_line(f"WARNING: {f} took {s:.0f} s CPU, over its allowance of {allowance(f, costs):.0f} s "
                      "(bound its sizes, share fixtures, move sweeps to benchmarks/: tests/ci_time.py)")
    if config.getoption("ci_costs_write"):
        merged = {**costs, **{f: round(s, 1) for f, s in tally.cpu.items()}}
        merged = {f: v for f, v in merged.items() if (ROOT / f).is_file()}  # files since removed: dropped
        COSTS.write_text(json.dumps(dict(sorted(merged.items())), indent=0) + "\n")
        tr.write_line(f"recorded the CPU time of {len(tally.cpu)} file(s) in {COSTS}")
    elif failing and os.environ.get("ROBOCAL_CPU_GATE") == "1":
        tr.write_line(f"FAILED: {len(failing)} test file(s) over {FAIL_FACTOR:g}× their CPU allowance "
                      f"(ROBOCAL_CPU_GATE=1): {', '.join(sorted(failing))}. Bound the file's sizes or share its fixtures; "
                      "a file that must cost this much records its cost in tests/ci_costs.json "
                      "(pytest FILE --ci-costs-write; null there: warned of, never failed)", red=True)
