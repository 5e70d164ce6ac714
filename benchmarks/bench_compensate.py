"""Benchmark: compensating a program of Cartesian targets (arc welder, Delta); target < 1 s for 10 000.

Targets: the nominal model's poses at joint configurations over the arc welder's jig workspace
(approach configurations of a touch-candidate pool, reused cyclically with small joint jitter),
the calibrated model the paper's Table 2 truth (~24 mm of correction).  `--n` sets the size.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from pipeline.compensate.serial import SerialArmKinematics, compensate
from pipeline.models import serial_arm
from pipeline.simulate.arc_welder import IK_SEEDS
from pipeline.systems import arc_welder as aw


def workspace_configs(n: int, seed: int = 0) -> np.ndarray:
    """n joint configurations around the jig (nominal IK of touch candidates, jittered by 0.05 rad)."""
    from pipeline.models.jig import stepped_block
    from pipeline.plan.touch import pool

    nominal = aw.nominal_arm()
    base = pool(nominal, stepped_block(), min(n, 300), seed=seed, margin_m=0.0).q_contact
    rng = np.random.default_rng(seed)
    q = base[np.arange(n) % base.shape[0]] + rng.normal(0, 0.05, (n, base.shape[1]))
    return np.clip(q, nominal.lower, nominal.upper)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    nominal, truth = aw.nominal_arm(), aw.reference_truth()
    kin = SerialArmKinematics.of(nominal)
    q = workspace_configs(a.n)
    R, p = serial_arm.forward(nominal.vector(), q)
    for label, hint in (("with the program's nominal joints (q_<joint> columns)", q), ("nominal IK from 8 seeds", None)):
        times = []
        for _ in range(a.repeats):
            t = time.perf_counter()
            c = compensate(kin, nominal.vector(), truth.vector(), p, R, IK_SEEDS, hint=hint)
            times.append(time.perf_counter() - t)
        ok = c.status == "ok"
        Rt, pt = serial_arm.forward(truth.vector(), c.q[ok])
        counts = {s: int((c.status == s).sum()) for s in sorted(set(c.status))}
        print(f"arc welder, {a.n} pose targets, {label}: best {min(times):.3f} s, median {np.median(times):.3f} s; "
              f"{counts}; round trip max {np.abs(pt - p[ok]).max():.2e} m; median correction "
              f"{np.median(c.correction_m[ok]) * 1e3:.2f} mm")


if __name__ == "__main__":
    main()
