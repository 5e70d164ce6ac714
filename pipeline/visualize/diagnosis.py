"""The diagnosis's visual proof in rerun (rerun-sdk 0.41): every plot of diagnosis.json.

`log_diagnosis(rec, run_dir_or_doc)` logs each plot found in the document (the layout of
`pipeline.diagnose.document.plots`, discovered by `pipeline.report.diagnosis.find_plots`: added-variable
plots of each finding and each `unexplained_where` entry, the measured vs re-simulated
residuals) as scatter series:

- entity ``diagnosis/plots/<nn>_<slug>/<series>`` — `rr.SeriesPoints` (static style) and one
  `rr.Scalars` column per series; lengths (`*_m`) in mm, others as they are;
- the x variable of plot ``nn`` is its own timeline ``diagnosis x <nn>`` (a duration timeline
  whose value in seconds is the x value in its SI unit: rad, s, m/s, a sign …), so a
  TimeSeriesView on that timeline shows the residuals against the located variable.

Returns the logged entity paths.  Nothing here computes: the numbers are diagnosis.json's.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

PALETTE = {"before": (200, 90, 60), "measured": (200, 90, 60), "after": (60, 160, 90), "effect": (60, 90, 200),
           "resimulated": (60, 90, 200), "smooth": (150, 60, 180)}


def _load(run_dir_or_doc: Any) -> dict | None:
    if isinstance(run_dir_or_doc, dict):
        return run_dir_or_doc
    p = Path(run_dir_or_doc)
    for cand in (p, p / "diagnose" / "diagnosis.json", p / "diagnosis.json"):
        if cand.is_file():
            return json.loads(cand.read_text())
    return None


def _slug(s: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", s).strip("_")[:60] or "plot"


def timeline_of(index: int) -> str:
    return f"diagnosis x {index:02d}"


def log_diagnosis(rec: rr.RecordingStream, run_dir_or_doc: Any) -> list[str]:
    """Log every plot of the diagnosis (module docstring); [] when there is none."""
    from pipeline.report.diagnosis import find_plots

    doc = _load(run_dir_or_doc)
    if not isinstance(doc, dict):
        return []
    paths: list[str] = []
    for i, p in enumerate(find_plots(doc)):
        base = f"diagnosis/plots/{i:02d}_{_slug(p.title)}"
        x = np.asarray(p.x, float)
        order = np.argsort(x, kind="stable")
        idx = rr.TimeColumn(timeline_of(i), duration=x[order])
        for name, y in p.series.items():
            length = name.endswith("_m")
            label = (name[:-2] if length else name)
            colour = next((c for k, c in PALETTE.items() if label.startswith(k)), (120, 120, 120))
            path = f"{base}/{_slug(label)}"
            rec.log(path, rr.SeriesPoints(colors=[colour], names=[f"{label} ({'mm' if length else p.y_label or '-'})"],
                                          marker_sizes=[3.0]), static=True)
            vals = np.asarray(y, float)[order] * (1e3 if length else 1.0)
            rec.send_columns(path, indexes=[idx], columns=rr.Scalars.columns(scalars=vals))
            paths.append(path)
        rec.log(f"{base}/title", rr.TextDocument(f"**{p.title}** — x: {p.x_label} (timeline `{timeline_of(i)}`)",
                                                   media_type=rr.MediaType.MARKDOWN), static=True)
    return paths
