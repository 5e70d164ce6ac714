"""Files other tools load, written beside model.json: a model offers ``exports(x)`` →
{file name: text} (a calibrated URDF, a D-H table)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_exports(model, x: np.ndarray, out: Path, std: np.ndarray | None = None,
                  free: np.ndarray | None = None) -> list[str]:
    """Write the model's exports for parameters x into `out`; the names written.  `std` (1σ per
    parameter) and `free` (fitted mask) go to models whose exports carry them (the physics sidecar)."""
    hook = getattr(model, "exports", None)
    if hook is None:
        return []
    files = hook(np.asarray(x, float), **_fit_kwargs(hook, std, free))
    for name, text in files.items():
        (Path(out) / name).write_text(text)
    return sorted(files)


def _fit_kwargs(hook, std, free) -> dict:
    import inspect

    params = inspect.signature(hook).parameters
    return {k: v for k, v in (("std", std), ("free", free)) if k in params and v is not None}


def describe(model, x: np.ndarray, std: np.ndarray | None = None, free: np.ndarray | None = None) -> dict:
    """model.json: the model's `describe(x)`, with σ and the fitted mask where it takes them."""
    return model.describe(np.asarray(x, float), **_fit_kwargs(model.describe, std, free))
