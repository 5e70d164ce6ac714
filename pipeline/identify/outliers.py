"""Identification with outlier rejection: fit, drop measurements whose residual is beyond
a robust threshold (MAD), refit, until none is left — naming every rejected record."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.identify.least_squares import Fit, FitOptions, fit
from pipeline.identify.model import MeasurementModel, Table, n_rows, take
from pipeline.validate.checks import robust_z


@dataclass
class RobustFit:
    fit: Fit
    kept: np.ndarray  # bool mask over the input rows
    rejected: list[dict] = field(default_factory=list)  # {"row", "record", "robust_z", "residual_m", "round"}


def fit_rejecting(model: MeasurementModel, data: Table, options: FitOptions = FitOptions(),
                  threshold: float = 5.0, max_rounds: int = 50, max_fraction: float = 0.2) -> RobustFit:
    """Fit; if the worst row's robust z (see `robust_z`) exceeds `threshold`, reject it and
    refit; repeat (one row per round, so a gross error does not drag good rows out with it).
    `threshold` ≤ 0 disables rejection; at most `max_fraction` of the rows are rejected."""
    n = n_rows(data)
    kept = np.ones(n, bool)
    record = np.asarray(data.get("record", np.arange(n)))
    f = fit(model, data, options)
    rejected: list[dict] = []
    if threshold <= 0:
        return RobustFit(f, kept, rejected)
    for rnd in range(1, max_rounds + 1):
        idx = np.flatnonzero(kept)
        z = robust_z(f.residuals_after)
        budget = int(max_fraction * n) - (n - kept.sum())
        worst = int(np.argmax(z))
        out = [worst] if budget > 0 and z[worst] > threshold else []
        if not out:
            break
        for i in out:
            r = f.residuals_after[i]
            rejected.append({"row": int(idx[i]), "record": int(record[idx[i]]), "robust_z": float(z[i]),
                             "residual_m": float(np.linalg.norm(r)), "round": rnd})
        kept[idx[out]] = False
        f = fit(model, take(data, kept), options)
    return RobustFit(f, kept, rejected)
