"""Visual proof of a diagnosis as plain arrays (pure numpy; drawn by the report and run.rrd).

Every plot is a dict ``{"title", "x_label", "y_label", "x": [...], "<series>_m": [...], ...}`` —
the layout `pipeline.report.diagnosis.find_plots` renders (series ending in ``_m`` are lengths, m)
and `pipeline.visualize.diagnosis.log_diagnosis` logs to rerun.

- `added_variable`: for a finding, against the variable it acts through (its *located*
  variable, per measurement): ``before_m`` the residual of the geometry-only fit (already
  partialled: ⊥ the geometric Jacobian at the optimum), ``effect_m`` the fitted effect with its
  geometric part projected out (what the geometry could not absorb), ``after_m`` the residual
  after modelling.  For vector residuals the component where the effect is largest is shown.
- `unexplained`: the same for a lack-of-fit variable, with ``smooth_m`` the fitted smooth that
  the final design does not span.
- `resimulation`: per residual component against time, the measured residual of the
  geometry-only model (model − measured) beside the re-simulated one — the difference the
  accepted effects make to the model's prediction of the campaign (r_geometry − r_final) —
  and the residual after modelling.
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.inference.projection import orthonormal, project_out

COMPONENTS = {1: ("",), 3: ("x", "y", "z")}


def _component_label(c: int, k: int) -> str:
    names = COMPONENTS.get(k)
    return "" if k == 1 else f", {names[c] if names else c} component"


def _list(a: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(a, float)]


def added_variable(effect, located: tuple[str, np.ndarray] | None, r_geo: np.ndarray, r_final: np.ndarray,
                   contribution: np.ndarray, Q_geometry: np.ndarray) -> list[dict]:
    """Added-variable plot of one finding (module docstring); arrays (n, k) m, `Q_geometry`
    (n·k, p) an orthonormal basis of the free geometric Jacobian."""
    n, k = r_geo.shape
    cp = project_out(contribution.reshape(n * k, 1), Q_geometry).reshape(n, k)
    c = int(np.argmax(np.sqrt(np.mean(cp**2, axis=0))))
    label, x = located if located is not None else ("measurement index", np.arange(n, dtype=float))
    return [{"title": f"{effect.name}@{effect.location}: added-variable plot{_component_label(c, k)}",
             "x_label": label, "y_label": "residual (m)", "x": _list(x),
             "before_m": _list(r_geo[:, c]), "effect_m": _list(cp[:, c]), "after_m": _list(r_final[:, c])}]


def unexplained(variable, r_geo: np.ndarray, r_final: np.ndarray, A: np.ndarray, k: int) -> list[dict]:
    """Residuals against a lack-of-fit variable that the final design A (n·k, q) leaves structured."""
    n = r_geo.shape[0]
    Bp = project_out(variable.columns, orthonormal(A))
    coef, *_ = np.linalg.lstsq(Bp, r_final.reshape(n * k), rcond=None)
    sm = (Bp @ coef).reshape(n, k)
    c = int(np.argmax(np.sqrt(np.mean(sm**2, axis=0))))
    x = np.asarray(variable.values, float)[::k] if np.asarray(variable.values).size == n * k else variable.values
    return [{"title": f"unexplained structure in {variable.name}{_component_label(c, k)}",
             "x_label": f"{variable.name} ({variable.unit})", "y_label": "residual (m)", "x": _list(x),
             "before_m": _list(r_geo[:, c]), "smooth_m": _list(sm[:, c]), "after_m": _list(r_final[:, c])}]


def resimulation(time_s: np.ndarray, r_geo: np.ndarray, r_final: np.ndarray, contributions: list[np.ndarray]) -> dict:
    """Measured vs re-simulated residuals per component (empty when nothing was accepted)."""
    if not contributions:
        return {"plots": []}
    n, k = r_geo.shape
    resim = r_geo - r_final
    return {"note": "model − measured residual of the geometry-only fit (measured) and the difference the "
                    "accepted effects make to the predicted campaign (re-simulated); after = residual of the "
                    "model with the findings",
            "plots": [{"title": f"measured vs re-simulated residual{_component_label(c, k)}",
                       "x_label": "time since start (s)", "y_label": "residual (m)", "x": _list(time_s),
                       "measured_m": _list(r_geo[:, c]), "resimulated_m": _list(resim[:, c]),
                       "after_m": _list(r_final[:, c])} for c in range(k)]}
