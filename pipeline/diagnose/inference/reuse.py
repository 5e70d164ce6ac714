"""What the diagnosis takes over from identify instead of computing it again: the geometric fit (step 1).

identify's least-squares solution (DIR/identify/fit.json: x, the free set its rank test and model choice left,
the covariance and σ) is the geometric fit the diagnosis would make when it is the same problem: the same
parameters, an ordinary least-squares fit (linear loss, not a MAP estimate of the shrinkage route), the same
rows (identify's rejected records dropped) and a stationary point of the free parameters.  Each is checked on
the table the diagnosis holds — the parameter names, σ recomputed from the residuals at x, and the
Gauss–Newton step from x, which must lower the cost by no more than `STATIONARY` of it (a fit that stopped
short is not taken) — so what is reused is what a fit would return, at the price of one residual and one
Jacobian instead of a nonlinear solve over a few hundred parameters (whose rank tests alone cost more
than the rest of the diagnosis on a whole robot).  Anything else: None, and the diagnosis fits.
"""

from __future__ import annotations

import numpy as np

from pipeline.identify.identifiability import Identifiability
from pipeline.identify.least_squares import Fit

STATIONARY = 1e-6  # relative cost decrease a Gauss–Newton step may still find at a converged solution
SIGMA_RTOL = 1e-6  # σ recomputed at x against identify's (the same rows and model)


def identify_fit(doc: dict, model, table) -> Fit | None:
    """identify's fit (`doc`: its fit.json) as a `Fit` of `model` on `table`, or None (module docstring)."""
    names = list(model.parameter_names())
    sel = doc.get("model_selection") or {}
    if (doc.get("names") != names or doc.get("loss", "linear") != "linear"
            or str(sel.get("method", "")).startswith("shrinkage") or doc.get("cov") is None):
        return None
    x = np.asarray(doc["x"], float)
    free = np.asarray(doc["free"], bool)
    r = np.asarray(model.residuals(x, table), float)
    if r.shape[0] != doc.get("n_used") or not free.any():
        return None
    m, p = r.size, int(free.sum())
    sigma = float(np.sqrt(np.sum(r**2) / max(m - p, 1)))
    if not np.isclose(sigma, float(doc["sigma_m"]), rtol=SIGMA_RTOL, atol=0.0):
        return None
    cols = getattr(type(model), "jacobian_columns", None)
    J = (cols(model, x, table, free) if cols is not None else model.jacobian(x, table)[:, :, free]).reshape(m, p)
    scale = np.linalg.norm(J, axis=0)
    scale[scale == 0] = 1.0
    step, *_ = np.linalg.lstsq(J / scale, -r.ravel(), rcond=None)
    rr = float(r.ravel() @ r.ravel())
    gain = rr - float(np.sum((r.ravel() + (J / scale) @ step) ** 2))
    if rr > 0 and gain > STATIONARY * rr:
        return None
    index = {n: i for i, n in enumerate(names)}
    reasons = {index[n]: str(why) for n, why in (doc.get("reasons") or {}).items() if n in index}
    std = np.asarray(doc.get("std", np.zeros(len(names))), float)
    return Fit(names=names, units=list(model.parameter_units()), nominal=np.asarray(doc.get("x0", x), float),
               x=x, identifiability=Identifiability(free=free, reasons=reasons, pivots=np.zeros(0),
                                                    order=np.zeros(0, int)),
               std=std, cov=np.asarray(doc["cov"], float), residuals_before=r, residuals_after=r, sigma=sigma,
               nfev=0, elapsed_s=0.0)
