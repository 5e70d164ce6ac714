"""Reprocess throughput: the same archive of small recordings in-process (serial), on a local process
pool and on Dask (LocalCluster), side by side; Dask's overhead per recording.

    python benchmarks/bench_reprocess.py [--recordings 200] [--contacts 12] [--workers 2] [--stages ingest,validate,identify]
        [--engines serial,processes,dask] [--repeats 1] [--probe 40] [--startup 0] [--phases 0]

Each recording is the bundled arc-welder campaign cut to its first CONTACTS contacts (copied to
RECORDINGS paths of a nested archive; each copy is a separate run).  Each engine runs as a user runs
it: `python -m pipeline reprocess ARCHIVE --engine E` in a fresh process, timed end to end.  Overhead
per recording (the table's column) = (wall × workers − Σ task wall times) / recordings: all a worker
slot spends outside a task, the one-off start included (the interpreter's start and imports, discovery
and hashing, the engine's start-up and shutdown, scheduling, writing the dataset, idling at the end, and
on a busy machine the CPU taken by the engine's own threads).  --phases N (default 1) splits it: the
one-off start, and the steady state per recording (each worker's span from its first task's start to
its last task's end, minus its tasks) — the cost that grows with the archive.  With --repeats N the engines run N times in alternating order (on a shared box
the load then weighs on each alike) and Dask's wall is compared with the process pool's, run by run:
the end-to-end figure.  --startup N times a LocalCluster's start-up and shutdown alone, workers
spawned (Dask's default) or forked from robocal's fork server; --probe N, Dask's own per-task cost
with tasks that only sleep (no CPU contention).
"""

from __future__ import annotations

import argparse
import compileall
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this checkout's robocal, as the CLI runs below (PYTHONPATH), not an installed one

from pipeline.fleet.dataset import read_results  # noqa: E402
from pipeline.recording.reader import read_recording  # noqa: E402
from pipeline.recording.writer import RecordingWriter  # noqa: E402

JS, TC = "/robot/joint_state", "/touch/contact"


def small_recording(path: Path, contacts: int) -> None:
    rec = read_recording(ROOT / "recordings" / "arc-welder-touch.mcap")
    cs = rec.messages[TC][:contacts]
    t_end = cs[-1]["timestamp_ns"] + 1_000_000_000
    msgs = [(JS, m) for m in rec.messages[JS] if m["timestamp_ns"] <= t_end] + [(TC, m) for m in cs]
    msgs.sort(key=lambda x: x[1]["timestamp_ns"])
    with RecordingWriter(path) as w:
        for k, v in rec.metadata.items():
            w.metadata(k, v)
        for topic, m in msgs:
            w.write(topic, m)


def _sleep(seconds: float) -> float:
    t = time.perf_counter()
    time.sleep(seconds)
    return time.perf_counter() - t


def scheduling_probe(workers: int, n: int = 40, seconds: float = 0.5) -> float:
    """Dask's own cost per task, without CPU contention: tasks that sleep (s per task)."""
    from distributed import as_completed

    from pipeline.fleet.engine import dask_client

    with dask_client(None, workers, None) as client:
        client.submit(_sleep, 0.0, pure=False).result()  # workers warm
        t0 = time.perf_counter()
        futs = [client.submit(_sleep, seconds, pure=False) for _ in range(n)]
        busy = sum(f.result() for f in as_completed(futs))
        return (time.perf_counter() - t0) * workers / n - busy / n


def run_engine(tmp: Path, engine: str, a: argparse.Namespace) -> float:
    """One end-to-end run of `robocal reprocess` on `engine`, a fresh process as a user runs it
    (interpreter, imports, discovery, hashing, the engine's start-up and shutdown); prints its row and
    returns its wall time (s)."""
    out = tmp / f"out-{engine}"
    cmd = [sys.executable, "-m", "pipeline", "reprocess", str(tmp / "archive"), "--out", str(out), "--engine", engine,
           "--workers", str(a.workers), "--stages", a.stages]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, check=False, env={**os.environ, "PYTHONPATH": str(ROOT)})
    wall = time.perf_counter() - t0
    if p.returncode != 0:  # every recording must pass (no expected figures beside the copies)
        raise SystemExit(f"{engine}: exit {p.returncode}: {p.stderr.strip()[-500:]}")
    rows = read_results(out).to_pylist()
    bad = [f"{r['recording']}: {r['status']}: {r['error']}" for r in rows if r["status"] != "pass"]
    assert len(rows) == a.recordings and not bad, bad[:3]
    w = 1 if engine == "serial" else a.workers
    task = sum(r["elapsed_s"] for r in rows)
    over = (wall * w - task) / len(rows)
    mean = task / len(rows)
    print(f"{engine:<10} {wall:8.1f} {len(rows) / wall:7.2f} {mean:7.3f} {over:15.3f} {100 * over / mean:8.1f}%"
          f"   load {os.getloadavg()[0]:.1f}", flush=True)
    shutil.rmtree(out)
    return wall


STARTUP = """
import json, sys, time
t0 = time.perf_counter()
from pipeline.fleet import engine
if sys.argv[1] == "spawn":  # Dask's default: each worker a fresh interpreter that imports distributed and robocal
    engine.FORK_SERVER, engine.fork_server.start = {}, lambda stages=None: None
t1 = time.perf_counter()
with engine.dask_client(None, int(sys.argv[2]), None, sys.argv[3].split(",")) as client:
    t2 = time.perf_counter()
print(json.dumps([t1 - t0, t2 - t1, time.perf_counter() - t2]))
"""


PHASES = """
import json, sys, time
def main():
    t0 = time.perf_counter()
    from pipeline.fleet.engine import reprocess_archive
    t = {"import": time.perf_counter() - t0}
    ev, done = {}, []
    res = reprocess_archive(sys.argv[2], sys.argv[3], stages=sys.argv[5].split(","), engine=sys.argv[1],
                            workers=int(sys.argv[4]), on_plan=lambda a, b: ev.setdefault("plan", time.perf_counter()),
                            on_start=lambda c: ev.setdefault("start", time.perf_counter()),
                            on_row=lambda r: done.append((time.perf_counter(), r["worker"], r["elapsed_s"],
                                                          time.process_time())))
    end = time.perf_counter()
    start = ev.get("start", ev["plan"])
    by = {}
    for at, w, e, _ in done:
        by.setdefault(w, []).append((at, e))
    first = min(v[0][0] - v[0][1] for v in by.values())  # the first task's start (its end − its wall)
    rest = sorted(e for v in by.values() for _, e in v[1:])
    med = rest[len(rest) // 2]
    task = sum(e for _, _, e, _ in done)
    busy = sum(v[-1][0] - (v[0][0] - v[0][1]) for v in by.values())  # each worker: first start to last end
    t.update(plan=ev["plan"] - t0 - t["import"], up=start - ev["plan"], to_first=first - t0, tasks=done[-1][0] - start,
             close=end - done[-1][0], first_extra=sum(v[0][1] - med for v in by.values()), median=med,
             steady=(busy - task) / len(done), mean=task / len(done),
             idle_end=sum(done[-1][0] - v[-1][0] for v in by.values()), total=(end - t0) * len(by) / len(done) - task / len(done),
             client_cpu=(done[-1][3] - done[0][3]) / (done[-1][0] - done[0][0]))  # this process, all threads, s/s
    print(json.dumps(t))
if __name__ == "__main__":
    main()
"""


def phases_probe(tmp: Path, a: argparse.Namespace) -> None:
    """Where each engine's wall goes, in-process timestamps (a fresh interpreter per run, engines alternating):
    import, discovery + hashing, engine up, tasks, shutdown; then the overhead per recording split into the
    one-off start (to the first task, and the workers' first tasks beyond the median task: imports, first
    touches of memory), the steady state (each worker's span from its first task's start to its last task's
    end, minus the tasks: scheduling, the engine's CPU) and the idle workers at the end."""
    import json

    for rep in range(a.phases):
        engines = [e for e in a.engines.split(",") if e and e != "serial"]
        for engine in engines if rep % 2 == 0 else engines[::-1]:
            out = tmp / f"phases-{engine}"
            p = subprocess.run([sys.executable, "-c", PHASES, engine, str(tmp / "archive"), str(out), str(a.workers),
                                a.stages], capture_output=True, text=True, check=True,
                               env={**os.environ, "PYTHONPATH": str(ROOT)})
            t = json.loads(p.stdout.strip().splitlines()[-1])
            pc = lambda x: f"{100 * x / t['mean']:.1f} %"  # noqa: E731 — of the mean task
            print(f"phases {engine:<10}: import {t['import']:.2f} s, discovery + hashing {t['plan']:.2f} s, engine up "
                  f"{t['up']:.2f} s, tasks {t['tasks']:.2f} s, shutdown {t['close']:.2f} s; first task starts at "
                  f"{t['to_first']:.2f} s, workers' first tasks +{t['first_extra']:.2f} s over the median "
                  f"{t['median']:.3f} s; overhead per recording: steady state {t['steady'] * 1e3:.1f} ms "
                  f"({pc(t['steady'])}), in all {t['total'] * 1e3:.1f} ms ({pc(t['total'])}; idle at the end "
                  f"{t['idle_end']:.2f} worker-s); the client process's CPU between the first and the last row "
                  f"{t['client_cpu'] * 1e3:.0f} ms/s   load {os.getloadavg()[0]:.1f}", flush=True)
            shutil.rmtree(out)


def startup_probe(workers: int, stages: str, repeats: int) -> None:
    """LocalCluster up (workers ready, robocal's stages imported) and closed, in a fresh interpreter each
    time, workers spawned (Dask's default) or forked from robocal's fork server, alternately."""
    import json

    times: dict[str, list[list[float]]] = {"spawn": [], "forkserver": []}
    for rep in range(repeats):
        for method in ("spawn", "forkserver") if rep % 2 == 0 else ("forkserver", "spawn"):
            p = subprocess.run([sys.executable, "-c", STARTUP, method, str(workers), stages], capture_output=True,
                               text=True, check=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
            times[method].append(json.loads(p.stdout.strip().splitlines()[-1]))
    for method, ts in times.items():
        med = [sorted(t[i] for t in ts)[len(ts) // 2] for i in range(3)]
        print(f"LocalCluster of {workers}, workers {method:<10}: import {med[0]:.2f} s, up {med[1]:.2f} s, "
              f"close {med[2]:.2f} s (medians of {len(ts)}; up + close {', '.join(f'{t[1] + t[2]:.2f}' for t in ts)} s)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recordings", type=int, default=200)
    ap.add_argument("--contacts", type=int, default=12)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--stages", default="ingest,validate,identify")
    ap.add_argument("--engines", default="serial,processes,dask")
    ap.add_argument("--repeats", type=int, default=1, help="runs of the engines, in alternating order; 0: only probes")
    ap.add_argument("--probe", type=int, default=40, help="sleep tasks (0.5 s) for Dask's own per-task cost; 0: none")
    ap.add_argument("--phases", type=int, default=1, help="runs per engine of the in-process phase timing "
                    "(one-off start vs steady state per recording); 0: none")
    ap.add_argument("--startup", type=int, default=0, help="repeats of the LocalCluster start-up + shutdown probe, "
                    "spawned vs fork-server workers; 0: none")
    a = ap.parse_args()
    compileall.compile_dir(ROOT / "pipeline", quiet=2)  # as installed (`make bytecode`): no engine compiles robocal
    with tempfile.TemporaryDirectory(prefix="bench-reprocess-") as tmp:
        tmp = Path(tmp)
        first = tmp / "archive" / "robot-000" / "m00.mcap"
        first.parent.mkdir(parents=True)
        small_recording(first, a.contacts)
        for i in range(1, a.recordings):
            p = tmp / "archive" / f"robot-{i // 12:03d}" / f"m{i % 12:02d}.mcap"
            p.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(first, p)
        print(f"{a.recordings} recordings of {a.contacts} contacts ({first.stat().st_size / 1e6:.2f} MB each), "
              f"stages {a.stages}, {a.workers} worker(s), load {os.getloadavg()[0]:.1f}")
        print(f"{'engine':<10} {'wall s':>8} {'rec/s':>7} {'task s':>7} {'overhead/rec s':>15} {'% of task':>9}   (overhead incl. the one-off start)",
              flush=True)
        walls: dict[str, list[float]] = {}
        for rep in range(a.repeats):
            engines = [e for e in a.engines.split(",") if e]  # none: only the probes
            for engine in engines if rep % 2 == 0 else engines[::-1]:
                walls.setdefault(engine, []).append(run_engine(tmp, engine, a))
        if a.phases:
            phases_probe(tmp, a)
    if "dask" in walls and "processes" in walls:
        gaps = [100 * (d / p - 1) for d, p in zip(walls["dask"], walls["processes"])]
        print(f"Dask wall vs process-pool wall, run by run: {', '.join(f'{g:+.1f} %' for g in gaps)} "
              f"(mean {sum(gaps) / len(gaps):+.1f} %; walls {sum(walls['dask']):.1f} vs {sum(walls['processes']):.1f} s)")
    if a.startup:
        startup_probe(a.workers, a.stages, a.startup)
    if a.probe:
        per = scheduling_probe(a.workers, a.probe)
        print(f"Dask's own cost per task (LocalCluster, {a.probe} tasks sleeping 0.5 s): {per * 1e3:.1f} ms "
              f"({100 * per / 0.5:.1f} % of 0.5 s)")


if __name__ == "__main__":
    main()
