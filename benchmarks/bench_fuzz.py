"""Fuzz robocal with the seeded mutation corpus of tests/fuzz_corpus.py, each case a real
`robocal run REC --out DIR --stages …` process, and print the classification table:
one-line error / success (nothing lost) / success with warning / traceback / hang / memory /
silent loss, per mutation class, with the worst CPU time and peak memory.

    .venv/bin/python benchmarks/bench_fuzz.py --per-class 40          # full size (≈ 330 cases)
    .venv/bin/python benchmarks/bench_fuzz.py --per-class 4 --stages ingest,validate   # bounded
    .venv/bin/python benchmarks/bench_fuzz.py --surfaces 24    # CSV, URDF, bags, campaigns, run folders, …
    .venv/bin/python benchmarks/bench_fuzz.py --surfaces 28 --classes options,outputs   # nonsense at the door

`--surfaces N` runs N cases of each surface of tests/fuzz_surfaces.py instead, in this process (their
actions are library calls: import, parse, read_bag, run_pipeline, plan…), each with its CPU time.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import threading
import time
from collections import Counter, defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from fuzz_corpus import CLASSES, cases, message_count, workdir  # noqa: E402
from hostile_support import BUNDLED  # noqa: E402

ROBOCAL = str(Path(sys.executable).parent / "robocal")
OUTCOMES = ("error", "ok", "warned", "traceback", "hang", "memory", "silent-loss", "unnamed-error")


def run_case(path: Path, out: Path, stages: str, original: int, timeout_s: float, mem_gb: float) -> tuple[str, float, float, str]:
    """(outcome, CPU s, peak RSS GB, detail) of one `robocal run` process (its own rusage, by wait4)."""
    proc = subprocess.Popen([ROBOCAL, "run", str(path), "--out", str(out), "--stages", stages],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"})
    buf: list[str] = []
    reader = threading.Thread(target=lambda: buf.append(proc.stderr.read()), daemon=True)
    reader.start()
    killed = threading.Event()
    timer = threading.Timer(timeout_s, lambda: (killed.set(), proc.kill()))
    timer.start()
    _, status, ru = os.wait4(proc.pid, 0)
    timer.cancel()
    proc.returncode = os.waitstatus_to_exitcode(status)
    reader.join(timeout=10)
    err = buf[0] if buf else ""
    cpu, peak_gb = ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1e6
    if killed.is_set():
        return "hang", cpu, peak_gb, f"over {timeout_s} s"
    if peak_gb > mem_gb:
        return "memory", cpu, peak_gb, f"peak {peak_gb:.2f} GB"
    if "Traceback" in err or proc.returncode not in (0, 2):
        return "traceback", cpu, peak_gb, err.strip().splitlines()[-1][:200] if err.strip() else f"exit {proc.returncode}"
    if proc.returncode == 2:
        line = [ln for ln in err.splitlines() if "robocal: error:" in ln]
        ok = len(line) == 1 and (str(path) in line[0] or path.name in line[0])
        return ("error" if ok else "unnamed-error"), cpu, peak_gb, (line or [err[-200:]])[0][:200]
    res = json.loads((out / "results.json").read_text())
    got = message_count(path)
    if got >= original:
        return "ok", cpu, peak_gb, res["summary"]["status"]
    if res["summary"]["status"] != "pass" and res["warnings"]:
        return "warned", cpu, peak_gb, res["warnings"][0][:200]
    return "silent-loss", cpu, peak_gb, f"{original - got} lost, status {res['summary']['status']}"


def surfaces(seed: int, per_class: int, show: int, classes: tuple[str, ...] = ()) -> None:
    """The surface corpus (tests/fuzz_surfaces.py) in this process: table of outcomes per surface
    (`classes`: those surfaces only)."""
    from fuzz_surfaces import FAILURES, SURFACES, classify, surface_cases

    classes = classes or SURFACES

    cols = ("error", "ok", "warned") + FAILURES
    table: dict[str, Counter] = defaultdict(Counter)
    examples: list[str] = []
    worst = (0.0, "")
    work = workdir()
    t0, n = time.monotonic(), 0
    try:
        for case in surface_cases(seed, per_class, classes):
            c0 = time.process_time()
            outcome, detail = classify(case, work / f"s{n}")
            worst = max(worst, (time.process_time() - c0, case.name))
            table[case.cls][outcome] += 1
            if outcome in FAILURES and len(examples) < show * 5:
                examples.append(f"{case.name}: {outcome}: {detail[-300:]}")
            shutil.rmtree(work / f"s{n}", ignore_errors=True)
            n += 1
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(f"robocal surface fuzz: {n} cases (seed {seed}, {per_class} per surface) in {time.monotonic() - t0:.0f} s")
    print(f"{'surface':10s} " + " ".join(f"{c:>17s}" for c in cols))
    for cls in classes:
        print(f"{cls:10s} " + " ".join(f"{table[cls][c]:>17d}" for c in cols))
    print(f"most CPU: {worst[0]:.1f} s ({worst[1]})")
    for e in examples:
        print(f"  {e}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--surfaces", type=int, default=0, help="run N cases of every surface of tests/fuzz_surfaces.py "
                    "(CSV, URDF, ROS 2 bags, campaigns, targets, run folders, archives, …) instead")
    ap.add_argument("--classes", default="", help="with --surfaces: these surfaces only (comma-separated, e.g. "
                    "options,outputs)")
    ap.add_argument("--per-class", type=int, default=40, help="cases per mutation class (default 40: ~330 cases)")
    ap.add_argument("--seed", type=int, default=15)
    ap.add_argument("--sources", default="delta-tracker,scorbot-scanner,arc-welder-touch")
    ap.add_argument("--stages", default="ingest,validate,identify")
    ap.add_argument("--timeout-s", type=float, default=30.0)
    ap.add_argument("--mem-gb", type=float, default=1.0)
    ap.add_argument("--show", type=int, default=3, help="examples printed per failing outcome")
    a = ap.parse_args()
    if a.surfaces:
        return surfaces(a.seed, a.surfaces, a.show, tuple(c for c in a.classes.split(",") if c))
    sources = tuple(s for s in a.sources.split(",") if s)
    originals = {s: message_count(BUNDLED[s]) for s in sources}
    work = workdir()
    table: dict[str, Counter] = defaultdict(Counter)
    examples: dict[str, list[str]] = defaultdict(list)
    worst_cpu, worst_mem = (0.0, ""), (0.0, "")
    t0 = time.monotonic()
    n = 0
    try:
        for case in cases(a.seed, a.per_class, sources):
            path = case.make(work)
            out = work / f"run-{n}"
            outcome, cpu, peak, detail = run_case(path, out, a.stages, originals[case.source], a.timeout_s, a.mem_gb)
            table[case.cls][outcome] += 1
            if outcome not in ("error", "ok", "warned") and len(examples[outcome]) < a.show:
                examples[outcome].append(f"{case.name}: {detail}")
            worst_cpu = max(worst_cpu, (cpu, case.name))
            worst_mem = max(worst_mem, (peak, case.name))
            path.unlink(missing_ok=True)
            shutil.rmtree(out, ignore_errors=True)
            n += 1
    finally:
        shutil.rmtree(work, ignore_errors=True)
    cols = [o for o in OUTCOMES]
    print(f"robocal fuzz: {n} cases (seed {a.seed}, {a.per_class} per class, sources {', '.join(sources)}, "
          f"stages {a.stages}) in {time.monotonic() - t0:.0f} s")
    print(f"{'class':10s} " + " ".join(f"{c:>13s}" for c in cols))
    for cls in CLASSES:
        print(f"{cls:10s} " + " ".join(f"{table[cls][c]:>13d}" for c in cols))
    tot = Counter()
    for c in table.values():
        tot.update(c)
    print(f"{'total':10s} " + " ".join(f"{tot[c]:>13d}" for c in cols))
    print(f"most CPU: {worst_cpu[0]:.1f} s ({worst_cpu[1]}); largest peak memory: {worst_mem[0]:.2f} GB ({worst_mem[1]})")
    for o, ex in examples.items():
        for e in ex:
            print(f"  {o}: {e}")


if __name__ == "__main__":
    main()
