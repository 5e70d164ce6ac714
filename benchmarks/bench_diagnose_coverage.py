"""Confidence-interval honesty of the diagnosis: for effects injected at a multiple of
their minimum detectable size, the z-scores (estimate − truth)/std over many noise seeds — mean,
standard deviation (1 when the reported std is honest) — and the 95 % CI coverage: the share of
the reported intervals (`ci95`, t-based with the parameter's `dof`) holding the truth, beside the
share inside ±1.96 std, with its binomial standard error.

Arc welder (default): the benchmark campaign of `bench_diagnose.py`, compliance J2/J3 and
pretravel at 4× MDS; `--effects NAME@LOC …` any library effect, injected as `bench_diagnose.py`
injects it (first parameter `--mult`× MDS, the others 0), with the co-selected findings tallied.  Scanner (`--system scanner`): the campaign of `bench_diagnose_scanner.py`
(MDS from each seed's clean diagnosis, as there), J4 scale, J2 scale and the
time offset at 4×.

    .venv/bin/python benchmarks/bench_diagnose_coverage.py [--seeds 200] [--first-seed 1000]
    .venv/bin/python benchmarks/bench_diagnose_coverage.py --effects encoder_eccentricity@J4 backlash@J3 --seeds 100
    .venv/bin/python benchmarks/bench_diagnose_coverage.py --system scanner --seeds 80 --first-seed 10000
"""

from __future__ import annotations

import argparse

import numpy as np

import bench_diagnose as b
import bench_diagnose_scanner as bs
from pipeline.simulate import effects as se

CASES = [("joint_compliance", "J2"), ("joint_compliance", "J3"), ("trigger_pretravel", "touch sensor")]
# (2x MDS: the same z as 4x to first order — the estimate error and the std do not depend on the size)
SCANNER_CASES = [("joint_scale", "J4", 4), ("joint_scale", "J2", 4), ("time_offset", "camera", 4)]


def summary(label: str, rows: list[tuple[float, bool, float | None]], runs: int) -> str:
    """One line: found, z mean/sd, coverage of ci95 (± binomial 1σ) and of ±1.96 std, median dof."""
    z = np.array([r[0] for r in rows])
    cov = float(np.mean([r[1] for r in rows]))
    dof = [np.inf if r[2] is None else r[2] for r in rows]
    return (f"{label}: found {z.size}/{runs}, z mean {z.mean():.2f}, z sd {z.std():.2f}, "
            f"95 % CI coverage {cov * 100:.1f} % ± {np.sqrt(cov * (1 - cov) / z.size) * 100:.1f} "
            f"(dof median {np.median(dof):.1f}; ±1.96 std: {np.mean(np.abs(z) < 1.96) * 100:.1f} %)")


def row(p: dict, truth: float) -> tuple[float, bool, float | None]:
    return (p["value"] - truth) / p["std"], p["ci95"][0] <= truth <= p["ci95"][1], p["dof"]


def clean_mds(targets, n_clean: int) -> dict:
    """MDS per candidate: median over the clean diagnoses of seeds 0..n_clean−1 (bench_diagnose: 5)."""
    runs = [{(c["effect"], c["location"]): c["min_detectable"] for c in b.one(targets, [], s)["candidates"]}
            for s in range(n_clean)]
    return {k: float(np.median([m[k] or np.inf for m in runs])) for k in runs[0]}


def welder(a) -> None:
    targets = se.plan_targets(b.NOM, b.JIG, b.CAMPAIGN, truth=b.TRUE)
    mds = clean_mds(targets, a.mds_clean)
    cases = [tuple(c.split("@", 1)) for c in a.effects] if a.effects else CASES
    if cases == [("all",)]:
        cases = b.EFFECTS
    pooled = []
    for name, loc in cases:
        value = a.mult * mds[(name, loc)]
        k = b.K_PARAM.get(name, 1)  # as bench_diagnose: (value, 0, …)
        rows, alone, extra = [], [], {}
        for seed in range(a.first_seed, a.first_seed + a.seeds):
            d = b.one(targets, [b.inj(name, loc, value, k)], seed)
            f = [x for x in d["findings"] if (x["effect"], x["location"]) == (name, loc)]
            if not f:
                continue
            others = [f"{x['effect']}@{x['location']}" for x in d["findings"] if x is not f[0]]
            rw = row(f[0]["parameters"][0], value)
            rows.append(rw)
            if others:
                for o in others:
                    extra[o] = extra.get(o, 0) + 1
            else:
                alone.append(rw)
            if a.verbose:
                print(f"  seed {seed} z {rw[0]:+.2f} covered {rw[1]} dof {rw[2]} "
                      f"others {others}", flush=True)
        print(summary(f"{name}@{loc} at {a.mult:g}x MDS", rows, a.seeds), flush=True)
        pooled += rows
        if extra:
            print(f"  co-selected: {extra}; alone: " + summary("runs with no other finding", alone, len(rows)),
                  flush=True)
    if len(cases) > 1:  # the effects share their noise seeds: not independent draws
        print(summary(f"pooled over {len(cases)} effects", pooled, a.seeds * len(cases)), flush=True)


def scanner(a) -> None:
    rows: dict = {c: [] for c in SCANNER_CASES}
    runs = dict.fromkeys(SCANNER_CASES, 0)
    misnamed = {c: [0, 0] for c in SCANNER_CASES}  # [runs naming another effect instead, of which listing the truth as a look-alike]
    for seed in range(a.first_seed, a.first_seed + a.seeds):
        mds = bs.mds_of(bs.run([], seed))
        for c in SCANNER_CASES:
            name, loc, mult = c
            if (name, loc) not in mds:
                continue
            sp, val = bs.spec(name, loc, mult * mds[(name, loc)])
            d = bs.run([sp], seed)
            runs[c] += 1
            f = [x for x in d["findings"] if (x["effect"], x["location"]) == (name, loc)]
            if f:
                rows[c].append(row(f[0]["parameters"][0], val * bs.in_fitted_gauge(name, d)))
            elif d["findings"]:
                misnamed[c][0] += 1
                misnamed[c][1] += any((a["effect"], a["location"]) == (name, loc)
                                      for x in d["findings"] for a in x.get("look_alikes", []))
    for c in SCANNER_CASES:
        print(summary(f"{c[0]}@{c[1]} at {c[2]}x MDS", rows[c], runs[c])
              + f"; another effect named instead in {misnamed[c][0]} (the truth among its look-alikes in {misnamed[c][1]})",
              flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--system", choices=("arc-welder", "scanner"), default="arc-welder")
    ap.add_argument("--seeds", type=int, default=200)  # binomial 1σ of a 95 % coverage: ±1.5 % (80 seeds: ±2.4 %)
    ap.add_argument("--first-seed", type=int, default=None, help="default 1000 (arc welder), 10000 (scanner)")
    ap.add_argument("--effects", nargs="*", default=None,
                    help="arc welder: NAME@LOCATION of library effects (default compliance J2/J3, pretravel; all: the 12 of bench_diagnose)")
    ap.add_argument("--mult", type=float, default=4.0, help="arc welder: injected size in MDS")
    ap.add_argument("--mds-clean", type=int, default=1,
                    help="arc welder: MDS = median over this many clean seeds from 0 (bench_diagnose: 5)")
    ap.add_argument("--verbose", action="store_true", help="arc welder: one line per seed")
    a = ap.parse_args()
    if a.first_seed is None:
        a.first_seed = 10_000 if a.system == "scanner" else 1000
    (scanner if a.system == "scanner" else welder)(a)


if __name__ == "__main__":
    main()
