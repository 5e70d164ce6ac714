"""The fork server a local cluster's workers are forked from: its preload covers every import of a
task (a worker's first task imports nothing), it is started early only when nothing is done yet, and
stopping it ends the process at once (no interpreter teardown holding the caller's pipes)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from pipeline.fleet import fork_server
from reprocess_support import ENV, FAST, small_archive

FIRST_TASK = """
import json, sys
from pipeline.fleet.fork_server import warm_worker
warm_worker(sys.argv[3].split(","))
import distributed  # as in the fork server
from pipeline.fleet.rows import reprocess_one
before = set(sys.modules)
row = reprocess_one(sys.argv[1], "r.mcap", "0", 1, sys.argv[2], sys.argv[3].split(","), None, "{}")
print(json.dumps({"status": row["status"], "new": sorted(set(sys.modules) - before)}))
"""


def test_a_warm_worker_s_first_task_imports_nothing(tmp_path):
    rec = small_archive(tmp_path / "a", robots=1, months=1)[0]
    p = subprocess.run([sys.executable, "-c", FIRST_TASK, str(rec), str(tmp_path / "run"), FAST],
                       capture_output=True, text=True, env=ENV, check=True)
    out = json.loads(p.stdout.strip().splitlines()[-1])
    assert out["status"] in ("pass", "warn") and out["new"] == [], out


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
        return True
    except ProcessLookupError:
        return False


def test_start_if_fresh_start_and_stop(tmp_path):
    from multiprocessing import forkserver

    (tmp_path / "done" / "results").mkdir(parents=True)
    (tmp_path / "done" / "results" / "part-1.parquet").write_bytes(b"")
    assert not fork_server.start_if_fresh(tmp_path / "done", ["ingest"])  # results there: wait for the plan
    assert forkserver._forkserver._forkserver_pid is None
    try:
        for _ in range(2):  # a second start after a stop preloads again (tests start several clusters)
            assert fork_server.start_if_fresh(tmp_path / "fresh", ["ingest"])
            pid = forkserver._forkserver._forkserver_pid
            assert pid is not None and _alive(pid)
            assert not fork_server.start(["ingest"])  # running: not this caller's to stop
            fork_server.stop()
            assert not _alive(pid)  # reaped: no zombie either
            assert forkserver._forkserver._forkserver_pid is None
    finally:
        fork_server.stop()


def test_an_error_of_the_run_is_not_replaced_by_one_of_the_cluster_s_close(tmp_path, monkeypatch):
    """The plan fails after the local cluster was brought up (here: the on_plan callback raises) and its
    close fails too: the run's error is the one raised; the fork server is stopped either way."""
    import pytest

    from pipeline.fleet import engine

    arch = tmp_path / "a"
    small_archive(arch, robots=1, months=2)
    real_close = engine.EarlyCluster.close

    def failing_close(self):
        real_close(self)
        raise RuntimeError("close failed")

    monkeypatch.setattr(engine.EarlyCluster, "close", failing_close)

    def on_plan(n, k):
        raise ValueError("the run's own error")

    with pytest.raises(ValueError, match="the run's own error"):
        engine.reprocess_archive(arch, tmp_path / "out", stages=FAST.split(","), workers=1, on_plan=on_plan)
    assert not fork_server._started

    def on_start(client):  # raised inside the cluster's context (run_tasks), where the close happens too
        raise ValueError("the run's own error, in the cluster")

    with pytest.raises(ValueError, match="in the cluster"):
        engine.reprocess_archive(arch, tmp_path / "out1", stages=FAST.split(","), workers=1, on_start=on_start)
    assert not fork_server._started
    with pytest.raises(RuntimeError, match="close failed"):  # a run that succeeded reports its close error
        engine.reprocess_archive(arch, tmp_path / "out2", stages=FAST.split(","), workers=1)
