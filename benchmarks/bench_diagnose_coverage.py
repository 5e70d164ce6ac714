"""Confidence-interval honesty of the arc-welder diagnosis (issue 7): for effects injected at 4×
their minimum detectable size on the benchmark campaign of `bench_diagnose.py`, the z-scores
(estimate − truth)/std over many noise seeds — mean, standard deviation (1 when the reported std
is honest) and the share inside ±1.96 std (95 % CI coverage).

    .venv/bin/python benchmarks/bench_diagnose_coverage.py [--seeds 80]
"""

from __future__ import annotations

import argparse

import numpy as np

import bench_diagnose as b
from pipeline.simulate import effects as se

CASES = [("joint_compliance", "J2"), ("joint_compliance", "J3"), ("trigger_pretravel", "touch sensor")]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=80)
    a = ap.parse_args()
    targets = se.plan_targets(b.NOM, b.JIG, b.CAMPAIGN, truth=b.TRUE)
    mds = {(c["effect"], c["location"]): c["min_detectable"] for c in b.one(targets, [], 0)["candidates"]}
    for name, loc in CASES:
        value = 4 * mds[(name, loc)]
        z = []
        for seed in range(1000, 1000 + a.seeds):
            d = b.one(targets, [b.inj(name, loc, value, 1)], seed)
            f = [x for x in d["findings"] if (x["effect"], x["location"]) == (name, loc)]
            if f:
                p = f[0]["parameters"][0]
                z.append((p["value"] - value) / p["std"])
        z = np.array(z)
        print(f"{name}@{loc} at 4x MDS: found {z.size}/{a.seeds}, z mean {z.mean():.2f}, z sd {z.std():.2f}, "
              f"95 % CI coverage {np.mean(np.abs(z) < 1.96) * 100:.0f} %", flush=True)


if __name__ == "__main__":
    main()
