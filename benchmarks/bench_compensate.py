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


def accuracy(seeds: int) -> None:
    """The compensated program on the true robot vs the calibration's predicted accuracy, 1 000
    new targets: arc welder (Table 2 truth, 100 noisy contacts) and Delta (random truth, paper campaign)."""
    from pipeline.compensate import delta as cd
    from pipeline.identify.least_squares import fit
    from pipeline.models import delta as dm
    from pipeline.models.delta import Delta
    from pipeline.models.jig import stepped_block
    from pipeline.plan.arc_welder import table_of
    from pipeline.simulate import delta_tracker as dsim
    from pipeline.simulate.arc_welder import Campaign, Noise, simulate
    from pipeline.systems import delta_tracker as dt

    def rms(v):
        return float(np.sqrt(np.mean(v**2)))

    nominal, truth = aw.nominal_arm(), aw.reference_truth()
    kin = SerialArmKinematics.of(nominal)
    model = aw.TouchModel(nominal)
    q = workspace_configs(1000, seed=99)
    R, p = serial_arm.forward(nominal.vector(), q)
    ratios = []
    for s in range(seeds):
        f = fit(model, table_of(simulate(nominal, truth, stepped_block(), Campaign(contacts=100, seed=s), Noise())))
        c = compensate(kin, nominal.vector(), f.x, p, R, IK_SEEDS, hint=q)
        ok = c.status == "ok"
        after = np.linalg.norm(serial_arm.tip_position(truth.vector(), c.q[ok]) - p[ok], axis=1)
        before = np.linalg.norm(serial_arm.tip_position(truth.vector(), q) - p, axis=1)
        _, Jp = model.points(f.x, {"joint_positions": c.q[ok]})
        Jp = Jp[:, :, f.free]
        sig = np.sqrt(np.einsum("nip,pq,niq->n", Jp, f.cov, Jp))
        ratios.append(rms(after) / rms(sig))
        print(f"arc welder seed {s}: uncompensated {rms(before) * 1e3:.2f} mm -> compensated {rms(after) * 1e3:.4f} mm "
              f"RMS (predicted 1σ {rms(sig) * 1e3:.4f} mm, ratio {ratios[-1]:.2f}); {ok.sum()} of 1000 ok")
    print(f"arc welder: ratio true/predicted over {seeds} calibrations: median {np.median(ratios):.2f}, "
          f"max {max(ratios):.2f}, <= 1.2 in {sum(r <= 1.2 for r in ratios)} of {seeds}")
    dr = []
    for s in range(seeds):
        tr = dsim.random_truth(np.random.default_rng(s))
        sm = dsim.simulate(Delta(), tr, dsim.Campaign(), dsim.Noise())
        dmod = dt.TrackerModel()
        f = fit(dmod, {"joint_positions": sm.q, "point": sm.point_t})
        val = dsim.simulate(Delta(), tr, dsim.Campaign(points=1000, seed=1000 + s), dsim.Noise(scale=0.0))
        Rt, t = dt.registration_matrix(tr.registration)

        def true_t(theta):
            return (dm.full_forward(Delta(), tr.beta, theta, extended=True)[0] - t) @ Rt

        targets = true_t(val.q)
        c = cd.compensate(dmod, f.nominal, f.x, targets)
        ok = c.status == "ok"
        after = np.linalg.norm(true_t(c.q[ok]) - targets[ok], axis=1)
        before = np.linalg.norm(true_t(c.q_nominal[ok]) - targets[ok], axis=1)
        _, J = dmod.points(f.x, {"joint_positions": c.q[ok]})
        J = J[:, :, f.free]
        sig = np.sqrt(np.einsum("nip,pq,niq->n", J, f.cov, J))
        dr.append(rms(after) / rms(sig))
        print(f"delta seed {s}: uncompensated {rms(before) * 1e3:.3f} mm -> compensated {rms(after) * 1e3:.4f} mm "
              f"(predicted {rms(sig) * 1e3:.4f} mm, ratio {dr[-1]:.2f})")
    print(f"delta: ratio median {np.median(dr):.2f}, max {max(dr):.2f}, <= 1.2 in {sum(r <= 1.2 for r in dr)} of {seeds}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--accuracy-seeds", type=int, default=0, help="also the true-robot accuracy over this many calibrations")
    a = ap.parse_args()
    if a.accuracy_seeds:
        accuracy(a.accuracy_seeds)
    nominal, truth = aw.nominal_arm(), aw.reference_truth()
    kin = SerialArmKinematics.of(nominal)
    q = workspace_configs(a.n)
    R, p = serial_arm.forward(nominal.vector(), q)
    for label, hint in (("with the program's nominal joints (q_<joint> columns)", q), ("nominal IK from 8 seeds", None)):
        times, cpu = [], []
        for _ in range(a.repeats):
            t, tc = time.perf_counter(), time.process_time()
            c = compensate(kin, nominal.vector(), truth.vector(), p, R, IK_SEEDS, hint=hint)
            times.append(time.perf_counter() - t)
            cpu.append(time.process_time() - tc)
        ok = c.status == "ok"
        Rt, pt = serial_arm.forward(truth.vector(), c.q[ok])
        counts = {s: int((c.status == s).sum()) for s in sorted(set(c.status))}
        print(f"arc welder, {a.n} pose targets, {label}: best {min(times):.3f} s wall ({min(cpu):.3f} s CPU), "
              f"median {np.median(times):.3f} s; "
              f"{counts}; round trip max {np.abs(pt - p[ok]).max():.2e} m; median correction "
              f"{np.median(c.correction_m[ok]) * 1e3:.2f} mm")


if __name__ == "__main__":
    main()
