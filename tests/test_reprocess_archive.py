"""`robocal reprocess ARCHIVE` on Dask: recursive discovery, a LocalCluster of 2 workers over a nested
archive (rows streamed to Parquet, regression gate, resume), a real `dask scheduler` + 2 `dask worker`
processes on loopback (--scheduler), the client SIGKILLed and resumed, workers killed mid-task (retried
by a nanny; recorded when the scheduler allows no failure)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import threading
import time

import pytest

from pipeline.fleet.dataset import read_results
from pipeline.fleet.discover import discover
from pipeline.fleet.engine import reprocess_archive
from pipeline.stages.artefacts import sha256_file
from reprocess_support import FAST, DaskCluster, cli, kill_group, small_archive


def test_discovery_is_recursive_and_stays_inside_the_archive(tmp_path):
    arch, outside = tmp_path / "archive", tmp_path / "elsewhere"
    (arch / "a" / "b").mkdir(parents=True)
    outside.mkdir()
    for p in (arch / "top.mcap", arch / "a" / "b" / "deep.mcap", arch / "a" / "notes.txt", outside / "x.mcap"):
        p.write_bytes(b"x")
    (arch / "a" / "out.mcap").symlink_to(outside / "x.mcap")          # file symlink out: skipped
    (arch / "linked-out").symlink_to(outside, target_is_directory=True)  # folder symlink out: skipped
    (arch / "alias").symlink_to(arch / "a", target_is_directory=True)    # inside, already searched: once
    (arch / "a" / "b" / "loop").symlink_to(arch, target_is_directory=True)  # a loop ends
    (arch / "in.mcap").symlink_to(arch / "top.mcap")                    # file symlink inside: kept
    (arch / "gone.mcap").symlink_to(arch / "nothing.mcap")              # broken: named
    found, skipped = discover(arch)
    rels = [f.rel for f in found]
    assert len(rels) == 3 and set(rels) == {"top.mcap", "in.mcap"} | {r for r in rels if r.endswith("deep.mcap")}
    assert any(s.startswith("a/out.mcap: symlink out") for s in skipped)
    assert any(s.startswith("linked-out: symlink out") for s in skipped)
    assert "gone.mcap: broken symlink" in skipped
    found, _ = discover(arch, ["a/**/*.mcap"])
    assert [f.rel for f in found] == ["a/b/deep.mcap"]


@pytest.fixture(scope="module")
def archive(tmp_path_factory):
    root = tmp_path_factory.mktemp("archive")
    recs = small_archive(root / "fleet")
    return root / "fleet", recs


def test_local_cluster_nested_archive_streams_rows_gates_and_resumes(archive, tmp_path):
    arch, recs = archive
    work = tmp_path / "arch"
    shutil.copytree(arch, work)
    (work / "robot-2" / "2026-03" / "junk.mcap").write_bytes(b"not an mcap")  # a failing task: a row
    (work / "robot-1" / "2026-02" / "campaign.expected.json").write_text(json.dumps(
        {"figures": {"n_measurements": {"equals": 12}, "rms_after_m": {"max": 1e-30}}}))  # a regression
    out = tmp_path / "out"
    p = cli("reprocess", work, "--out", out, "--workers", "2", "--stages", FAST)
    stdout, stderr = p.communicate(timeout=300)
    assert p.returncode == 1, stderr
    assert "2 worker(s)" in stderr and "21/21" in stderr  # the progress bar's count
    t = read_results(out)
    rows = {r["recording"]: r for r in t.to_pylist()}
    assert len(rows) == 21 and t.num_rows == 21
    good = rows["robot-3/2026-04/campaign.mcap"]
    assert good["robot_id"] == "robot-3" and good["robot_id_source"] == "recording"
    assert good["input_sha256"] == sha256_file(work / "robot-3/2026-04/campaign.mcap")
    assert good["system"] == "arc-welder" and good["n_measurements"] == 12 and good["ok"]
    assert good["campaign_start_ns"] > 1.7e18 and good["robocal_version"]
    free = [q for q in good["parameters"] if q["identifiable"]]
    assert len(good["parameters"]) == 42 and len(free) == good["n_identifiable"] and all(q["std"] > 0 for q in free)
    bad = rows["robot-2/2026-03/junk.mcap"]
    assert bad["status"] == "error" and "not an MCAP file" in bad["error"] and not bad["ok"]
    reg = rows["robot-1/2026-02/campaign.mcap"]
    assert reg["regressions"] and reg["regressions"][0].startswith("rms_after_m") and not reg["ok"]
    assert len({r["worker"] for r in rows.values()}) == 2  # both worker processes ran tasks
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["rows"]) == 21 and not summary["ok"]

    # resume: nothing left to do; --robot-id (a different option set) recomputes every row with it
    p = cli("reprocess", work, "--out", out, "--workers", "2", "--stages", FAST)
    _, stderr = p.communicate(timeout=120)
    assert p.returncode == 1 and "21 done before" in stderr
    assert read_results(out, latest=False).num_rows == 21
    p = cli("reprocess", work / "robot-4", "--out", tmp_path / "out4", "--engine", "serial", "--stages", FAST,
            "--robot-id", "R4-serial-0042")
    _, stderr = p.communicate(timeout=120)
    assert p.returncode == 0, stderr
    rows4 = read_results(tmp_path / "out4").to_pylist()
    assert len(rows4) == 5 and {r["robot_id"] for r in rows4} == {"R4-serial-0042"}
    assert {r["robot_id_source"] for r in rows4} == {"override"}

    # nothing left to do: no cluster is started (its thread would be up when the plan is known) ...
    plans = []
    seen = lambda n, k: plans.append((n, k, {t.name for t in threading.enumerate()}))  # noqa: E731
    reprocess_archive(work, out, stages=FAST.split(","), workers=2, on_plan=seen)
    assert plans[0][:2] == (0, 21) and "robocal-cluster" not in plans[0][2]
    # ... but one as soon as a recording needs a run, brought up while the rest is hashed
    shutil.copyfile(recs[0], work / "robot-1" / "new.mcap")
    reprocess_archive(work, out, stages=FAST.split(","), workers=2, on_plan=seen)
    assert plans[1][:2] == (1, 21) and "robocal-cluster" in plans[1][2]


@pytest.mark.extended  # `make test-extended`: a third Dask archive run; CI keeps the external scheduler and local cluster tests
def test_resume_after_the_client_is_killed(archive, tmp_path):
    arch, recs = archive
    recs = [r for r in recs if r.relative_to(arch).parts[0] in ("robot-1", "robot-2")]
    out, pattern = tmp_path / "out", "robot-[12]/**/*.mcap"
    # rows flushed 0.1 s after they finish, so the kill lands after the first rows and before the last
    p = cli("reprocess", arch, "--out", out, "--workers", "2", "--stages", FAST, "--pattern", pattern, "--flush-s", "0.1")
    t0 = time.monotonic()
    while not list((out / "results").glob("part-*.parquet")):
        assert time.monotonic() - t0 < 120 and p.poll() is None, "no part written"
        time.sleep(0.05)
    kill_group(p)  # SIGKILL: the client and its local cluster
    before = read_results(out).to_pylist()
    assert 1 <= len(before) < 10
    p = cli("reprocess", arch, "--out", out, "--workers", "2", "--stages", FAST, "--pattern", pattern)
    _, stderr = p.communicate(timeout=300)
    assert p.returncode == 0, stderr
    assert f"{len(before)} done before" in stderr
    every = read_results(out, latest=False).to_pylist()
    assert len(every) == 10  # nothing computed twice
    assert {r["recording"] for r in every} == {r.relative_to(arch).as_posix() for r in recs}


def test_external_scheduler_and_a_worker_killed_mid_task(archive, tmp_path):
    """A real scheduler (allowed-failures 0: a task whose worker dies is not retried) and two workers."""
    from distributed import Client

    arch, _ = archive
    cluster = DaskCluster(tmp_path, 2, {"DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": "0"})
    try:
        with Client(cluster.address, timeout="30s") as c:
            c.wait_for_workers(2, timeout=60)
            pids = c.run(os.getpid)
        out = tmp_path / "out"
        p = cli("reprocess", arch / "robot-1", "--out", out, "--scheduler", cluster.address, "--stages", FAST)
        _, stderr = p.communicate(timeout=300)
        assert p.returncode == 0, stderr
        rows = read_results(out).to_pylist()
        assert len(rows) == 5 and all(r["ok"] for r in rows)
        assert {int(r["worker"].split(":")[1]) for r in rows} <= set(pids.values())

        # kill one worker while it executes a task: that row is recorded as lost, the rest complete
        out2 = tmp_path / "out2"
        p = cli("reprocess", arch, "--out", out2, "--scheduler", cluster.address, "--stages", FAST,
                "--pattern", "robot-[23]/**/*.mcap")
        victim = _kill_when_executing(cluster.address, pids)
        _, stderr = p.communicate(timeout=300)
        assert p.returncode == 1, stderr
        rows = read_results(out2).to_pylist()
        lost = [r for r in rows if r["status"] == "lost"]
        # the task it was executing, and one it may already hold (Dask's queue sends a worker ⌈1.1 × threads⌉)
        assert len(rows) == 10 and 1 <= len(lost) <= 2, [r["status"] for r in rows]
        assert all("KilledWorker" in r["error"] and not r["ok"] for r in lost)
        assert all(r["input_sha256"] == sha256_file(r["path"]) for r in lost)  # hashed by the client for the row
        assert all(r["ok"] for r in rows if r["status"] != "lost")
        assert all(int(r["worker"].split(":")[1]) != victim for r in rows if r["ok"])
    finally:
        cluster.close()


def _kill_when_executing(address: str, pids: dict, timeout: float = 120) -> int:
    """Wait until a worker is executing a task, SIGKILL it, return its pid."""
    from distributed import Client

    with Client(address, timeout="30s") as c:
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            busy = c.run(lambda dask_worker: dask_worker.state.executing_count)
            for addr, n in busy.items():
                if n:
                    os.kill(pids[addr], signal.SIGKILL)
                    return pids[addr]
            time.sleep(0.05)
    raise AssertionError("no task started")


def test_local_cluster_retries_a_task_whose_worker_died(archive, tmp_path):
    """LocalCluster with nannies: a worker SIGKILLed mid-task is restarted (forked again from robocal's fork
    server) and the task re-run (Dask's own retry): every row ok, none lost.  The workers are forked from the
    fork server, not spawned by this process, and run BLAS on one thread."""
    from pipeline.fleet.engine import reprocess_archive

    arch, _ = archive
    killed, facts = [], {}

    def on_start(client):
        def worker_facts() -> tuple[int, list[int]]:
            import threadpoolctl

            return os.getppid(), [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]

        facts.update(client.run(worker_facts))
        pids = client.run(os.getpid)

        def kill():
            t0 = time.monotonic()
            while time.monotonic() - t0 < 120 and not killed:
                try:
                    busy = client.run(lambda dask_worker: dask_worker.state.executing_count)
                except Exception:  # noqa: BLE001
                    return
                for addr, n in busy.items():
                    if n and not killed:
                        os.kill(pids[addr], signal.SIGKILL)
                        killed.append(pids[addr])
                time.sleep(0.05)

        threading.Thread(target=kill, daemon=True).start()

    res = reprocess_archive(arch / "robot-4", tmp_path / "out", stages=FAST.split(","), workers=2,
                            on_start=on_start)
    assert len(facts) == 2 and all(ppid != os.getpid() and blas and set(blas) == {1} for ppid, blas in facts.values()), facts
    assert killed
    assert len(res.rows) == 5 and all(r["ok"] for r in res.rows), [r["status"] for r in res.rows]
    assert all(int(r["worker"].split(":")[1]) != killed[0] for r in res.rows)


def test_results_writer_puts_a_row_on_disk_within_flush_s_and_parts_are_complete(tmp_path):
    from pipeline.fleet.dataset import ResultsWriter
    from pipeline.fleet.rows import SCHEMA

    row = {f.name: None for f in SCHEMA} | {"recording": "a.mcap", "warnings": [], "parameters": [],
                                             "regressions": []}
    with ResultsWriter(tmp_path, flush_s=0.3) as w:
        w.add(row)
        t0 = time.monotonic()
        while not list((tmp_path / "results").glob("part-*.parquet")):
            assert time.monotonic() - t0 < 5, "the buffered row was not flushed by the timer"
            time.sleep(0.02)
        w.add(row | {"recording": "b.mcap"})
        w.add(row | {"recording": "a.mcap", "status": "pass"})  # a newer row of a.mcap
    assert not list((tmp_path / "results").glob(".*tmp"))
    latest = {r["recording"]: r["status"] for r in read_results(tmp_path).to_pylist()}
    assert latest == {"a.mcap": "pass", "b.mcap": None} and read_results(tmp_path, latest=False).num_rows == 3


def test_plan_hashes_only_what_a_previous_row_may_cover(archive, tmp_path):
    """A recording never run is a task at once (hashed by the task, of the bytes it reads: the row's
    input_sha256); one with a row in OUT is hashed by the plan: kept when unchanged, re-run when its
    bytes changed."""
    from pipeline.fleet.engine import plan

    arch, recs = archive
    work = tmp_path / "arch"
    shutil.copytree(arch / "robot-4", work)
    out = tmp_path / "out"
    tasks, kept, _ = plan(work, out, stages=FAST.split(","))
    assert len(tasks) == 5 and not kept and all(t.sha256 is None for t in tasks)
    res = reprocess_archive(work, out, stages=FAST.split(","), engine="serial")
    assert all(r["input_sha256"] == sha256_file(work / r["recording"]) for r in res.rows)
    changed = work / "2026-02" / "campaign.mcap"
    shutil.copyfile(recs[0], changed)  # robot-1's recording: other bytes at a path already done
    shutil.copyfile(recs[0], work / "new.mcap")
    tasks, kept, _ = plan(work, out, stages=FAST.split(","))
    assert len(kept) == 4 and {t.found.rel: t.sha256 for t in tasks} == {
        "2026-02/campaign.mcap": sha256_file(changed), "new.mcap": None}
