"""Why a reprocess task is slower in a Dask worker than in a process pool: the same task, one worker,
in several contexts, interleaved; and the CPU Dask's own housekeeping burns while idle.

    python benchmarks/bench_dask_worker.py [--tasks 12] [--repeats 2] [--contexts pool,pool-thread,dask-default,dask]
        [--idle-s 6]

Per task (means; the first two of each batch dropped as warm-up): wall; the task thread's CPU (what the
task itself computes); the CPU of the worker process's other threads during the task (Dask's event loop:
while it runs it holds the GIL, so the task thread waits even on a free core, and on a busy box it takes
the core); the task thread's voluntary context switches (GIL hand-offs, I/O); garbage collection time.
Contexts: `pool` a forked ProcessPoolExecutor (the `processes` engine), `pool-thread` a spawned pool
process running the task in a second thread (as a Dask worker's executor does), `dask-default`
a LocalCluster with Dask's default housekeeping and spawned workers (robocal's QUIET only, as before),
`dask` robocal's LocalCluster (`fleet/engine.dask_client`: fork server, RELAXED housekeeping).
Then, with --idle-s, each LocalCluster idle: CPU per second of a worker and of the client process
(scheduler and nannies), Dask's defaults against RELAXED.
"""

from __future__ import annotations

import argparse
import logging
import multiprocessing as mp
import os
import shutil
import statistics
import sys
import tempfile
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench_reprocess import small_recording  # noqa: E402

from pipeline.fleet import engine  # noqa: E402
from pipeline.fleet.fork_server import warm_worker  # noqa: E402
from pipeline.fleet.rows import reprocess_one  # noqa: E402

STAGES = ["ingest", "validate", "identify"]


def timed(*args) -> tuple[float, float, float, int, float]:
    """reprocess_one(*args): (wall s, task-thread CPU s, other threads' CPU s, voluntary switches, gc s)."""
    import gc
    import resource

    acc = [0.0, 0.0]

    def on_gc(phase: str, info: dict) -> None:
        if phase == "start":
            acc[1] = time.perf_counter()
        else:
            acc[0] += time.perf_counter() - acc[1]

    gc.callbacks.insert(0, on_gc)
    r0 = resource.getrusage(resource.RUSAGE_THREAD)
    t, c, ct = time.perf_counter(), time.process_time(), time.thread_time()
    reprocess_one(*args)
    wall, cpu, tcpu = time.perf_counter() - t, time.process_time() - c, time.thread_time() - ct
    r1 = resource.getrusage(resource.RUSAGE_THREAD)
    gc.callbacks.remove(on_gc)
    return wall, tcpu, cpu - tcpu, r1.ru_nvcsw - r0.ru_nvcsw, acc[0]


def timed_in_thread(*args) -> tuple:
    out: list = []
    th = threading.Thread(target=lambda: out.append(timed(*args)))
    th.start()
    th.join()
    return out[0]


def run_pool(method: str, fn, batch: list[tuple]) -> list[tuple]:
    with ProcessPoolExecutor(1, mp_context=mp.get_context(method), initializer=warm_worker) as pool:
        return [f.result() for f in [pool.submit(fn, *a) for a in batch]]


def default_cluster(workers: int = 1):
    """A LocalCluster as robocal made it before: Dask's default housekeeping, spawned workers (QUIET only)."""
    import dask
    from distributed import Client, LocalCluster

    @contextmanager
    def cm():
        with dask.config.set(engine.QUIET), \
                LocalCluster(n_workers=workers, threads_per_worker=1, dashboard_address=None, scheduler_port=0,
                             silence_logs=logging.ERROR, env=engine.SINGLE_THREADED | engine.QUIET_ENV) as cl, \
                Client(cl) as client:
            client.run(warm_worker, STAGES)
            yield client
    return cm()


def run_dask(relaxed: bool, batch: list[tuple]) -> list[tuple]:
    with (engine.dask_client(None, 1, None, STAGES) if relaxed else default_cluster()) as client:
        return [f.result() for f in [client.submit(timed, *a, pure=False) for a in batch]]


CONTEXTS = {
    "pool": lambda b: run_pool("fork", timed, b),
    "pool-thread": lambda b: run_pool("spawn", timed_in_thread, b),
    "dask-default": lambda b: run_dask(False, b),
    "dask": lambda b: run_dask(True, b),
}


def idle_cpu(relaxed: bool, seconds: float) -> tuple[float, float]:
    """(worker, client process) CPU in ms per second of an idle 1-worker LocalCluster."""
    import psutil

    with (engine.dask_client(None, 1, None, STAGES) if relaxed else default_cluster()) as client:
        worker = psutil.Process(next(iter(client.run(os.getpid).values())))
        me = psutil.Process()
        time.sleep(1.0)
        w0, m0 = sum(worker.cpu_times()[:2]), sum(me.cpu_times()[:2])
        time.sleep(seconds)
        w1, m1 = sum(worker.cpu_times()[:2]), sum(me.cpu_times()[:2])
    return 1e3 * (w1 - w0) / seconds, 1e3 * (m1 - m0) / seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tasks", type=int, default=12)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--contexts", default=",".join(CONTEXTS))
    ap.add_argument("--idle-s", type=float, default=6.0, help="idle CPU probe length; 0: none")
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench-dask-worker-"))
    try:
        rec = tmp / "m.mcap"
        small_recording(rec, 12)
        names = a.contexts.split(",")
        res: dict[str, list[tuple]] = {n: [] for n in names}
        print(f"{a.tasks} tasks × {a.repeats} repeats per context, 1 worker, load {os.getloadavg()[0]:.1f}")
        for rep in range(a.repeats):
            for name in names if rep % 2 == 0 else names[::-1]:
                batch = [(str(rec), "m.mcap", "-", 0, str(tmp / f"{name}-{rep}" / f"r{i}"), STAGES, None, "{}")
                         for i in range(a.tasks)]
                res[name] += CONTEXTS[name](batch)[2:]
                shutil.rmtree(tmp / f"{name}-{rep}")
        print(f"{'context':<13} {'wall s':>7} {'task CPU s':>10} {'others CPU s':>12} {'vol. switches':>13} {'gc ms':>6}")
        for name, out in res.items():
            m = [statistics.mean(o[i] for o in out) for i in range(5)]
            print(f"{name:<13} {m[0]:7.3f} {m[1]:10.3f} {m[2]:12.4f} {m[3]:13.1f} {1e3 * m[4]:6.2f}")
        if a.idle_s:
            for relaxed in (False, True):
                w, c = idle_cpu(relaxed, a.idle_s)
                print(f"idle LocalCluster, {'RELAXED' if relaxed else 'Dask defaults'}: worker {w:.1f} ms/s, "
                      f"client process (scheduler, nanny) {c:.1f} ms/s")
        print(f"load {os.getloadavg()[0]:.1f}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
