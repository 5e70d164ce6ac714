"""Pose planning for any measurement model: free parameters from the rank test over all
candidates, D-optimal choice (`doptimal.select`), and the check on simulated data that the
planned set beats random sets of the same size on held-out accuracy."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from pipeline.identify.identifiability import analyse
from pipeline.identify.least_squares import FitOptions, fit
from pipeline.identify.model import MeasurementModel, Table, n_rows, take
from pipeline.observe.indices import indices, singular_values
from pipeline.plan.doptimal import Selection, select


@dataclass
class Plan:
    selection: Selection
    free: np.ndarray  # bool over the model's parameters
    observability: dict[str, float]  # O1..O5 of the selected set (free parameters)


def plan(model: MeasurementModel, candidates: Table, m: int, x: np.ndarray | None = None,
         extra: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None) -> Plan:
    """Pick m candidates maximising log det of the free parameters' information at x (nominal); with `extra`
    (Jacobian (N, k, P), free mask → (N, k, E) columns of further terms planned for) of the free parameters'
    and those terms' information together (observability: of the free parameters alone)."""
    x = model.nominal() if x is None else x
    J = model.jacobian(x, candidates)  # (N, k, P)
    priority = getattr(model, "priority", lambda: None)()
    ident = analyse(J.reshape(-1, J.shape[-1]), model.parameter_names(), priority=priority)
    A = J[:, :, ident.free]
    sel = select(A if extra is None else np.concatenate([A, extra(J, ident.free)], axis=2), m)
    Js = A[sel.index].reshape(-1, A.shape[-1])
    return Plan(sel, ident.free, indices(singular_values(Js), Js.shape[0]))


def holdout_rms(model: MeasurementModel, train: Table, test: Table, options: FitOptions = FitOptions(),
                error: Callable[[np.ndarray, Table], np.ndarray] | None = None) -> float:
    """RMS on `test` of the model fitted to `train`: of its residuals (m), or of `error(x_fitted, test)`."""
    f = fit(model, train, options)
    e = model.residuals(f.x, test) if error is None else error(f.x, test)
    return float(np.sqrt(np.mean(e ** 2)))


def compare(model: MeasurementModel, candidates: Table, test: Table, m: int, n_random: int = 20,
            seed: int = 0, error: Callable[[np.ndarray, Table], np.ndarray] | None = None) -> dict:
    """Held-out RMS of the planned m-set vs `n_random` random m-sets of the same candidates
    (of the residuals, or of `error(x_fitted, test)`, see `holdout_rms`)."""
    p = plan(model, candidates, m)
    planned = holdout_rms(model, take(candidates, p.selection.index), test, error=error)
    rng = np.random.default_rng(seed)
    N = n_rows(candidates)
    rand = []
    for _ in range(n_random):
        idx = np.sort(rng.choice(N, m, replace=False))
        rand.append(holdout_rms(model, take(candidates, idx), test, error=error))
    rand = np.array(rand)
    return {"m": m, "n_candidates": N, "n_test": n_rows(test), "planned_holdout_rms_m": planned,
            "random_holdout_rms_m": rand.tolist(), "random_median_m": float(np.median(rand)),
            "planned_rank_among_random": int(np.sum(rand < planned)), "selection_s": p.selection.elapsed_s,
            "planned_index": p.selection.index.tolist(), "logdet": p.selection.logdet,
            "observability": p.observability}
