"""Files other tools load, written beside model.json: a model offers ``exports(x)`` →
{file name: text} (a calibrated URDF, a D-H table)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_exports(model, x: np.ndarray, out: Path) -> list[str]:
    """Write the model's exports for parameters x into `out`; the names written."""
    hook = getattr(model, "exports", None)
    if hook is None:
        return []
    files = hook(np.asarray(x, float))
    for name, text in files.items():
        (Path(out) / name).write_text(text)
    return sorted(files)
