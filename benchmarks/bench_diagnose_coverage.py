"""Confidence-interval honesty of the arc-welder diagnosis (issue 7): for effects injected at 4×
their minimum detectable size on the benchmark campaign of `bench_diagnose.py`, the z-scores
(estimate − truth)/std over many noise seeds — mean, standard deviation (1 when the reported std
is honest) — and the 95 % CI coverage: the share of the reported intervals (`ci95`, t-based with
the parameter's `dof`) holding the truth, beside the share inside ±1.96 std, with its binomial
standard error.

    .venv/bin/python benchmarks/bench_diagnose_coverage.py [--seeds 200] [--first-seed 1000]
"""

from __future__ import annotations

import argparse

import numpy as np

import bench_diagnose as b
from pipeline.simulate import effects as se

CASES = [("joint_compliance", "J2"), ("joint_compliance", "J3"), ("trigger_pretravel", "touch sensor")]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=200)  # binomial 1σ of a 95 % coverage: ±1.5 % (80 seeds: ±2.4 %)
    ap.add_argument("--first-seed", type=int, default=1000)
    a = ap.parse_args()
    targets = se.plan_targets(b.NOM, b.JIG, b.CAMPAIGN, truth=b.TRUE)
    mds = {(c["effect"], c["location"]): c["min_detectable"] for c in b.one(targets, [], 0)["candidates"]}
    for name, loc in CASES:
        value = 4 * mds[(name, loc)]
        z, inside, dof = [], [], []
        for seed in range(a.first_seed, a.first_seed + a.seeds):
            d = b.one(targets, [b.inj(name, loc, value, 1)], seed)
            f = [x for x in d["findings"] if (x["effect"], x["location"]) == (name, loc)]
            if f:
                p = f[0]["parameters"][0]
                z.append((p["value"] - value) / p["std"])
                inside.append(p["ci95"][0] <= value <= p["ci95"][1])
                dof.append(np.inf if p["dof"] is None else p["dof"])
        z, cov = np.array(z), float(np.mean(inside))
        print(f"{name}@{loc} at 4x MDS: found {z.size}/{a.seeds}, z mean {z.mean():.2f}, z sd {z.std():.2f}, "
              f"95 % CI coverage {cov * 100:.1f} % ± {np.sqrt(cov * (1 - cov) / z.size) * 100:.1f} "
              f"(dof median {np.median(dof):.1f}; ±1.96 std: {np.mean(np.abs(z) < 1.96) * 100:.1f} %)", flush=True)


if __name__ == "__main__":
    main()
