"""What every measurement model offers the generic stages (identify, observe, plan, diagnose).

A measurement model is a description (parameter names, units, nominal values) plus pure
functions of (parameter vector x, measurement table).  A measurement table is a plain
``dict[str, np.ndarray]`` whose arrays share their first axis: one row per measurement.
Each measurement gives ``residual_dim`` residuals in metres.
"""

from __future__ import annotations

from typing import Mapping, Protocol, runtime_checkable

import numpy as np

Table = Mapping[str, np.ndarray]


def n_rows(table: Table) -> int:
    """Number of measurements in a table."""
    lengths = {len(v) for v in table.values()}
    if len(lengths) > 1:
        raise ValueError(f"table columns differ in length: {sorted(lengths)}")
    return lengths.pop() if lengths else 0


def take(table: Table, idx: np.ndarray) -> dict[str, np.ndarray]:
    """Rows `idx` (indices or boolean mask) of every column."""
    return {k: np.asarray(v)[idx] for k, v in table.items()}


def uncalibrated(model: "MeasurementModel", table: Table) -> np.ndarray:
    """The parameters of the system before calibration — the reference of every "RMS before".

    The nominal model, plus what must be known before any comparison is possible (a laser
    tracker's registration to the robot base): a model offers that through an optional
    ``uncalibrated(table)`` method.  A solver's data-driven start (`initial_guess`) is not
    this: it may already be fitted.
    """
    hook = getattr(model, "uncalibrated", None)
    return np.asarray(hook(table), float) if hook is not None else model.nominal()


@runtime_checkable
class MeasurementModel(Protocol):
    """A calibration system's model of its measurements (see module docstring)."""

    system: str
    residual_dim: int

    def parameter_names(self) -> list[str]: ...

    def parameter_units(self) -> list[str]: ...

    def nominal(self) -> np.ndarray:
        """Nominal parameter vector: the start of identification."""

    def residuals(self, x: np.ndarray, data: Table) -> np.ndarray:
        """Model minus measurement, (n, residual_dim) in m."""

    def jacobian(self, x: np.ndarray, data: Table) -> np.ndarray:
        """d residuals / d x, (n, residual_dim, n_params)."""

    def points(self, x: np.ndarray, data: Table) -> tuple[np.ndarray, np.ndarray]:
        """Predicted 3-D points the user cares about (tool tip, scanned point…) at each
        measurement, (n,3) m, and their Jacobian wrt x, (n,3,n_params)."""

    def describe(self, x: np.ndarray) -> dict:
        """The model file (JSON, `schemas/robot_model.schema.json`) for parameter vector x."""
