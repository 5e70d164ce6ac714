"""Scanner (seed 001) benchmark: global convergence over random truths, LM vs GA on the
paper's campaign (held-out 3-D error and time).  Prints figures; run:

    .venv/bin/python benchmarks/bench_scanner.py [--truths 200] [--ga-generations 10000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.optimize import least_squares

from pipeline.identify.genetic import GAOptions, fit_ga
from pipeline.identify.least_squares import fit
from pipeline.simulate import scorbot_scanner as sim
from pipeline.systems import scorbot_scanner as sc

ARM = sc.nominal_arm()


def reference_rms(model: sc.ScannerModel, table: dict, truth: np.ndarray) -> float:
    """RMS at the local optimum next to the truth (LM from the truth, only f fixed)."""
    free = np.ones(14, bool)
    free[0] = False
    x = truth.copy()

    def fun(z):
        x[free] = z
        return model.residuals(x, table).ravel()

    def jac(z):
        x[free] = z
        return model.jacobian(x, table).reshape(-1, 14)[:, free]
    sol = least_squares(fun, truth[free], jac=jac, method="lm", x_scale="jac", xtol=1e-14, ftol=1e-14)
    return float(np.sqrt(np.mean(sol.fun**2)))


def convergence(n: int) -> None:
    rng = np.random.default_rng(2026)
    ratios, times, i = [], [], 0
    while len(ratios) < n:
        i += 1
        truth = sc.random_scanner(rng)
        try:
            _, table = sim.simulate_in_memory(ARM, ARM, truth, sim.Campaign(seed=i), sim.Noise())
        except RuntimeError:
            continue  # this truth cannot see 5 corners from reachable poses: not a usable scanner
        model = sc.ScannerModel(arm=ARM)
        t0 = time.perf_counter()
        f = fit(model, table)
        times.append(time.perf_counter() - t0)
        ratios.append(f.rms_after / reference_rms(model, table, truth))
    r = np.array(ratios)
    ok = r <= 1.05
    print(f"global convergence: {ok.sum()}/{n} random truths within 5 % of the optimum's RMS "
          f"({100 * ok.mean():.1f} %; {(r <= 1.01).sum()} within 1 %); RMS ratio median {np.median(r):.5f}, max {r.max():.4f}; "
          f"{i - n} drawn truths unusable (stripe not visible from reachable poses)")
    print(f"calibration time (global search + LM) per truth: median {np.median(times):.3f} s, max {max(times):.3f} s")


def paper_campaign(ga_generations: int) -> None:
    truth = sc.reference_scanner()
    _, train = sim.simulate_in_memory(ARM, ARM, truth, sim.Campaign(seed=0), sim.Noise())
    tests = [sim.simulate_in_memory(ARM, ARM, truth, sim.Campaign(seed=s), sim.Noise())[1] for s in range(100, 110)]
    model = sc.ScannerModel(arm=ARM)
    fit(model, train)  # warm-up (imports)
    t_lm = []
    for _ in range(10):
        t0 = time.perf_counter()
        f_lm = fit(model, train)
        t_lm.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    f_ga = fit_ga(model, train, GAOptions(generations=ga_generations))
    t_ga = time.perf_counter() - t0

    def held_out(x):
        return np.concatenate([np.linalg.norm(model.residuals(x, t), axis=1) for t in tests])
    floor = held_out(truth)
    print("paper campaign (5 poses x 5 corners, default noise), held-out: 10 new campaigns (new poses, new corners)")
    print(f"{'':24s}{'mean':>9s}{'RMS':>9s}{'max':>9s}  (3-D error, mm){'time':>12s}")
    for name, x, t in (("noise floor (truth)", truth, None), ("LM (global + LM)", f_lm.x, np.median(t_lm)),
                       (f"GA ({f_ga.nfev // 100} gen.)", f_ga.x, t_ga)):
        e = held_out(x) * 1e3
        ts = f"{t:10.3f} s" if t is not None else ""
        print(f"{name:24s}{e.mean():9.3f}{np.sqrt(np.mean(e**2)):9.3f}{e.max():9.3f}{'':17s}{ts}")
    print(f"training residual RMS: LM {f_lm.rms_after * 1e3:.4f} mm, GA {f_ga.rms_after * 1e3:.4f} mm; "
          f"floor mean/max {floor.mean() * 1e3:.3f}/{floor.max() * 1e3:.3f} mm")


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--truths", type=int, default=200)
    ap.add_argument("--ga-generations", type=int, default=10000)
    a = ap.parse_args()
    paper_campaign(a.ga_generations)
    convergence(a.truths)
