"""Benchmark: arc-welder calibration solve time at 100 contacts, and its growth to 100 000.

Run: .venv/bin/python benchmarks/bench_calibrate.py
Larger campaigns are drawn (with replacement) from a simulated 2 000-contact campaign:
the solver's cost depends on the number of rows, not on their being distinct.
"""

from __future__ import annotations

import time

import numpy as np

from pipeline.identify.least_squares import fit
from pipeline.models.jig import stepped_block
from pipeline.simulate.arc_welder import Campaign, simulate
from pipeline.systems import arc_welder as aw


def main() -> None:
    nominal = aw.nominal_arm()
    sim = simulate(nominal, aw.reference_truth(), stepped_block(), Campaign(contacts=2000, seed=7))
    full = {"joint_positions": sim.contact_q, "axis": sim.contact_axis, "coordinate": sim.contact_coordinate}
    model = aw.TouchModel(nominal)
    rng = np.random.default_rng(0)
    print("contacts  solve_s   per_contact_us  rms_after_mm  identified")
    for n in (100, 1_000, 10_000, 100_000):
        idx = np.arange(100) if n == 100 else rng.integers(0, 2000, n)
        data = {k: v[idx] for k, v in full.items()}
        reps = 5 if n <= 1000 else 1
        best = np.inf
        for _ in range(reps):
            t = time.perf_counter()
            f = fit(model, data)
            best = min(best, time.perf_counter() - t)
        print(f"{n:8d}  {best:7.3f}   {best / n * 1e6:10.1f}      {f.rms_after * 1e3:.4f}      {int(f.free.sum())}")


if __name__ == "__main__":
    main()
