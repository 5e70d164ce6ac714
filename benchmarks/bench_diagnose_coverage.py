"""Confidence-interval honesty of the diagnosis (issue 7): for effects injected at a multiple of
their minimum detectable size, the z-scores (estimate − truth)/std over many noise seeds — mean,
standard deviation (1 when the reported std is honest) — and the 95 % CI coverage: the share of
the reported intervals (`ci95`, t-based with the parameter's `dof`) holding the truth, beside the
share inside ±1.96 std, with its binomial standard error.

Arc welder (default): the benchmark campaign of `bench_diagnose.py`, compliance J2/J3 and
pretravel at 4× MDS.  Scanner (`--system scanner`): the campaign of `bench_diagnose_scanner.py`
(MDS from each seed's clean diagnosis, as there), J4 scale, J2 scale and the
time offset at 4×.

    .venv/bin/python benchmarks/bench_diagnose_coverage.py [--seeds 200] [--first-seed 1000]
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


def welder(a) -> None:
    targets = se.plan_targets(b.NOM, b.JIG, b.CAMPAIGN, truth=b.TRUE)
    mds = {(c["effect"], c["location"]): c["min_detectable"] for c in b.one(targets, [], 0)["candidates"]}
    for name, loc in CASES:
        value = 4 * mds[(name, loc)]
        rows = []
        for seed in range(a.first_seed, a.first_seed + a.seeds):
            d = b.one(targets, [b.inj(name, loc, value, 1)], seed)
            f = [x for x in d["findings"] if (x["effect"], x["location"]) == (name, loc)]
            if f:
                rows.append(row(f[0]["parameters"][0], value))
        print(summary(f"{name}@{loc} at 4x MDS", rows, a.seeds), flush=True)


def scanner(a) -> None:
    rows: dict = {c: [] for c in SCANNER_CASES}
    runs = dict.fromkeys(SCANNER_CASES, 0)
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
    for c in SCANNER_CASES:
        print(summary(f"{c[0]}@{c[1]} at {c[2]}x MDS", rows[c], runs[c]), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--system", choices=("arc-welder", "scanner"), default="arc-welder")
    ap.add_argument("--seeds", type=int, default=200)  # binomial 1σ of a 95 % coverage: ±1.5 % (80 seeds: ±2.4 %)
    ap.add_argument("--first-seed", type=int, default=None, help="default 1000 (arc welder), 10000 (scanner)")
    a = ap.parse_args()
    if a.first_seed is None:
        a.first_seed = 10_000 if a.system == "scanner" else 1000
    (scanner if a.system == "scanner" else welder)(a)


if __name__ == "__main__":
    main()
