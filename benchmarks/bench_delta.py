"""Delta + laser tracker (seed 003): speed and accuracy figures.

Run:  .venv/bin/python benchmarks/bench_delta.py [--quick]

Prints
  1. solve time of the paper's 27-point campaign (fit = start + rank test + LM + covariance);
  2. how the cost grows with the number of points (fit and one residual+Jacobian evaluation);
  3. noise-free β' truth: held-out 3-D position error over the workspace box;
  4. default noise, paper campaign, several seeds: held-out RMS / noise floor, Fig. 6 distance ratio;
  5. `full` truth: the residual the simplified model leaves, and the extended model's.
"""

from __future__ import annotations

import os

# one BLAS thread: on a small, shared machine threaded BLAS makes the tiny QR/SVD calls of a fit
# 10-50x slower and the figures erratic
for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from pipeline.identify.least_squares import cross_validate, fit  # noqa: E402
from pipeline.models.delta import Delta  # noqa: E402
from pipeline.simulate import delta_tracker as sim  # noqa: E402
from pipeline.systems.delta_tracker import TrackerModel  # noqa: E402

DELTA = Delta()
UM = 1e6


def campaign(seed: int = 0, truth_model: str = "simplified", noise_scale: float = 1.0, **kw):
    truth = sim.random_truth(np.random.default_rng(seed + 1_000_003), truth_model)
    s = sim.simulate(DELTA, truth, sim.Campaign(seed=seed, **kw), sim.Noise(scale=noise_scale))
    return truth, s, {"joint_positions": s.q, "point": s.point_t}


def timed(f, repeat: int, clock=time.perf_counter) -> float:
    ts = []
    for _ in range(repeat):
        t = clock()
        f()
        ts.append(clock() - t)
    return float(np.median(ts))


def main(quick: bool = False) -> None:
    rep = 5 if quick else 20
    simple, extended = TrackerModel(), TrackerModel(variant="extended")

    print("== 1. solve time, paper campaign (27 points, 3x3x3 grid, 150/150/40 mm) ==")
    _, _, tab = campaign()
    for m in (simple, extended):
        fit(m, tab)
        t = timed(lambda: fit(m, tab), rep)
        c = timed(lambda: fit(m, tab), rep, clock=time.process_time)
        f = fit(m, tab)
        print(f"  {m.variant:10s}: {t * 1e3:7.1f} ms wall, {c * 1e3:7.1f} ms CPU  (median of {rep}; {f.nfev} evaluations, "
              f"{int(f.free.sum())}/{len(f.names)} parameters identified)")

    print("== 2. cost vs number of points (simplified model) ==")
    print(f"  {'points':>6s} {'fit ms':>8s} {'res+jac ms':>11s} {'us/point':>9s}")
    for n in (27, 100, 300, 1000, 3000) if not quick else (27, 300):
        _, _, t_ = campaign(points=n)
        x = fit(simple, t_).x
        tf = timed(lambda: fit(simple, t_), max(3, rep // 4))
        te = timed(lambda: (simple.residuals(x, t_), simple.jacobian(x, t_)), rep)
        print(f"  {n:6d} {tf * 1e3:8.1f} {te * 1e3:11.3f} {te / n * 1e6:9.2f}")

    print("== 3. noise-free, beta' truth: held-out over the workspace box (1000 random points) ==")
    truth, _, tab = campaign(noise_scale=0.0)
    f = fit(simple, tab)
    v = sim.simulate(DELTA, truth, sim.Campaign(points=1000, seed=77), sim.Noise(scale=0.0))
    e = np.linalg.norm(simple.residuals(f.x, {"joint_positions": v.q, "point": v.point_t}), axis=1)
    print(f"  3-D error: RMS {np.sqrt(np.mean(e**2)) * UM:.2e} um, max {e.max() * UM:.2e} um "
          f"(before calibration RMS {np.sqrt(np.mean(f.residuals_before**2)) * UM:.1f} um per axis)")

    print("== 4. default noise (0.02 mm/axis), paper campaign, 5-fold held-out ==")
    print(f"  {'seed':>4s} {'floor um':>8s} {'after um':>8s} {'held-out um':>11s} {'ratio':>6s} {'3-D ho um':>9s} "
          f"{'ratio amp before->after':>24s} {'std before->after':>20s}")
    ratios, reductions, std_red = [], [], []
    for seed in range(4 if quick else 10):
        _, s, tab = campaign(seed=seed)
        f = fit(simple, tab)
        ho = cross_validate(simple, tab, k=5)
        floor = s.measurement_error_rms_m
        r = float(np.sqrt(np.mean(ho**2)) / floor)
        d = simple.extra_metrics(f.nominal, f.x, tab)["distance_ratio"]
        ratios.append(r)
        reductions.append(d["amplitude_reduction"])
        std_red.append(1 - d["std_after"] / d["std_before"])
        print(f"  {seed:4d} {floor * UM:8.2f} {np.sqrt(np.mean(f.residuals_after**2)) * UM:8.2f} "
              f"{np.sqrt(np.mean(ho**2)) * UM:11.2f} {r:6.3f} {np.sqrt(np.mean(np.sum(ho**2, 1))) * UM:9.2f} "
              f"{d['max_abs_dev_before'] * 100:10.3f}% -> {d['max_abs_dev_after'] * 100:.3f}% "
              f"{d['std_before'] * 100:9.3f}% -> {d['std_after'] * 100:.3f}%")
    print(f"  held-out/floor: mean {np.mean(ratios):.3f}, max {np.max(ratios):.3f};  distance-ratio amplitude "
          f"shrinks by {np.mean(reductions) * 100:.0f} % on average (min {np.min(reductions) * 100:.0f} %), "
          f"std by {np.mean(std_red) * 100:.0f} % (seed 003 Fig. 6: ~20 %)")
    print(f"  (least squares with p = 21 parameters on 0.8x81 residuals cannot beat sqrt(1 + p/m) = "
          f"{np.sqrt(1 + 21 / (0.8 * 81)):.2f} on held-out points)")

    print("== 5. full truth (axis directions 0.25 deg, unequal rods 0.2 mm): what beta' leaves ==")
    for scale, kw in ((0.0, {}), (1.0, {}), (1.0, {"points": 300})):
        truth, s, tab = campaign(seed=2, truth_model="full", noise_scale=scale, **kw)
        v = sim.simulate(DELTA, truth, sim.Campaign(points=500, seed=78), sim.Noise(scale=0.0))
        val = {"joint_positions": v.q, "point": v.point_t}
        row = []
        for m in (simple, extended):
            f = fit(m, tab)
            ho = cross_validate(m, tab, k=5)
            row.append(f"{m.variant}: fit {np.sqrt(np.mean(f.residuals_after**2)) * UM:6.2f} um, held-out "
                       f"{np.sqrt(np.mean(ho**2)) * UM:6.2f} um, workspace {np.sqrt(np.mean(m.residuals(f.x, val)**2)) * UM:6.2f} um")
        label = f"{kw['points']} random points" if kw else "27-point grid"
        print(f"  {label}, noise x{scale:g} (floor {s.measurement_error_rms_m * UM:.2f} um): " + " | ".join(row))


if __name__ == "__main__":
    main(quick="--quick" in sys.argv)
