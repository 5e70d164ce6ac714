"""The outlier screen of validate on run folders that have run ingest: its first robust fit as it stands
(`pipeline.validate.outlier_fit.first_fit`, one soft-L1 solve over the parameters identifiable at the start)
beside the fit it replaced (identify's full `fit` — rank re-tests and negative-compliance refusals — each solve
capped at 200 evaluations) and beside that full fit run to convergence (cap 5000): CPU, evaluations, converged,
the records flagged (robust z > 6) and the largest z.

    python benchmarks/bench_validate_screen.py RUN [RUN …]     # RUN: a folder of `robocal run … --stages ingest`
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from pipeline.identify.least_squares import FitOptions, fit
from pipeline.ingest.tables import model_columns
from pipeline.stages.ingest import load_system, read_measurements
from pipeline.validate.checks import robust_z
from pipeline.validate.outlier_fit import first_fit


def main() -> None:
    print("run | rows | screen | CPU s | evaluations (last solve) | converged | free | flagged records (z > 6) | max z")
    for run in map(Path, sys.argv[1:]):
        _, model, _ = load_system(run)
        table = read_measurements(run)
        data = model_columns(table)
        scale = getattr(model, "robust_scale", None) or 1e-4
        screens = {"first_fit (now)": lambda: first_fit(model, data, scale),
                   "full fit, cap 200 (before)": lambda: fit(model, data, FitOptions(loss="soft_l1", f_scale=scale,
                                                                                     max_nfev=200)),
                   "full fit, cap 5000": lambda: fit(model, data, FitOptions(loss="soft_l1", f_scale=scale,
                                                                             max_nfev=5000))}
        for label, go in screens.items():
            c0 = time.process_time()
            f = go()
            cpu = time.process_time() - c0
            z = robust_z(f.residuals_after)
            flagged = np.asarray(table["record"])[z > 6.0].tolist()
            print(f"{run.name} | {len(table['record'])} | {label} | {cpu:.2f} | {f.nfev} | {f.converged} | "
                  f"{int(f.free.sum())} | {flagged} | {z.max():.1f}", flush=True)


if __name__ == "__main__":
    main()
