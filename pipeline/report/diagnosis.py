"""Generic reading of diagnosis.json (the residual diagnosis) for the report: plots found in the document, plus
added-variable plots against each finding's located variable.

The report does not depend on the diagnosis's exact layout.  `find_plots` takes any object in the
document that carries an ``x`` array and one or more arrays of the same length (a plot), e.g.::

    {"title": "...", "x_label": "time since start (s)", "x": [...],
     "before_m": [...], "after_m": [...]}          # or "series": {"before_m": [...], ...}

Series whose name ends in ``_m`` are lengths (shown in mm).  For a finding whose ``location``
names a column of ingest/measurements.parquet (``time_since_start_s``, ``q_J2``, ``v_J1``,
``dir_J3``, a joint name …), `located_plots` draws the geometric fit's residuals against it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class PlotSpec:
    """One x-vs-series plot in SI units (series names keep their `_m` suffix)."""

    title: str
    x_label: str
    x: np.ndarray
    series: dict[str, np.ndarray] = field(default_factory=dict)
    y_label: str = ""

    @property
    def lengths(self) -> bool:
        return all(k.endswith("_m") for k in self.series)


def _numeric(v: Any, n: int | None = None) -> np.ndarray | None:
    if not isinstance(v, list) or not v or (n is not None and len(v) != n):
        return None
    try:
        a = np.asarray(v, float)
    except (TypeError, ValueError):
        return None
    return a if a.ndim == 1 else None


def _as_plot(d: dict, title: str, marked: bool = False) -> PlotSpec | None:
    """A plot: ``x`` plus same-length series, and either under a ``plot``/``plots`` key (`marked`) or
    labelled (``x_label`` or ``series``) — so that e.g. a parameter vector ``x`` is not taken for one."""
    x = _numeric(d.get("x"))
    if x is None or not (marked or "x_label" in d or isinstance(d.get("series"), dict)):
        return None
    src = d.get("series") if isinstance(d.get("series"), dict) else d
    series = {k: a for k, v in src.items() if k not in ("x",) and (a := _numeric(v, x.size)) is not None}
    if not series:
        return None
    return PlotSpec(title=str(d.get("title") or title), x_label=str(d.get("x_label") or d.get("variable") or "x"),
                    x=x, series=series, y_label=str(d.get("y_label") or ""))


def find_plots(doc: Any, title: str = "diagnosis", depth: int = 0, marked: bool = False) -> list[PlotSpec]:
    """Every plot-shaped object in the diagnosis document (depth-first, document order)."""
    if depth > 6:
        return []
    out: list[PlotSpec] = []
    if isinstance(doc, dict):
        p = _as_plot(doc, title, marked)
        if p is not None:
            return [p]
        label = str(doc.get("effect") or doc.get("name") or title)
        for k, v in doc.items():
            plot_key = k in ("plot", "plots")
            out += find_plots(v, label if plot_key else f"{label}: {k}", depth + 1, plot_key)
    elif isinstance(doc, list):
        for v in doc:
            out += find_plots(v, title, depth + 1, marked)
    return out


def _location_column(location: Any, columns: list[str]) -> str | None:
    cands: list[str] = []
    if isinstance(location, dict):
        cands += [str(v) for k, v in location.items() if k in ("variable", "column", "joint", "name")]
    elif location is not None:
        cands.append(str(location))
    for c in cands:
        for form in (c, f"q_{c}"):
            if form in columns:
                return form
    return None


# the variable an effect acts through, by a word in its name ({joint} = the finding's location)
EFFECT_VARIABLES = (("backlash", "dir_{joint}"), ("thermal", "time_since_start_s"), ("drift", "time_since_start_s"),
                    ("latency", "v_{joint}"), ("pretravel", "v_{joint}"))


def _effect_column(effect: str, location: Any, columns: list[str]) -> str | None:
    joint = location if isinstance(location, str) else (location or {}).get("joint", "") if isinstance(location, dict) else ""
    if str(joint).startswith("temperature ") and "temperature_rise_K" in columns:
        return "temperature_rise_K"  # thermal drift located on a recorded temperature channel
    for word, pattern in EFFECT_VARIABLES:
        if word in effect.lower():
            c = pattern.format(joint=joint)
            if c in columns:
                return c
    return None


def located_plots(doc: dict, measurements: dict[str, np.ndarray] | None, residuals: dict[str, np.ndarray],
                  prismatic: frozenset = frozenset()) -> list[PlotSpec]:
    """Residuals of the geometric fit against each finding's located variable (added-variable view;
    joint readings in deg, a prismatic joint's in mm)."""
    if not measurements or "record" not in measurements:
        return []
    cols = list(measurements)
    unit = doc.get("residual_unit", "m")  # px for a camera: not a length, drawn as is
    key = "geometric fit residual_m" if unit == "m" else f"geometric fit residual ({unit})"
    pos = {int(r): i for i, r in enumerate(measurements["record"])}
    idx = np.array([pos.get(int(r), -1) for r in residuals["record"]])
    ok = idx >= 0
    out = []
    for f in doc.get("findings", []) or []:
        if not isinstance(f, dict):
            continue
        col = (_effect_column(str(f.get("effect", "")), f.get("location"), cols)
               or _location_column(f.get("location"), cols) or _location_column(f.get("variable"), cols))
        if col is None or "after_0" not in residuals:
            continue
        x = np.asarray(measurements[col], float)[idx[ok]]
        if col.startswith("q_"):
            from pipeline.report.labels import joint_scale

            scale, unit = joint_scale(col[2:], prismatic)
            x, label = x * scale, f"{col[2:]} ({unit})"
        else:
            label = col
        out.append(PlotSpec(title=f"{f.get('effect', 'finding')}: residuals of the geometric fit against {label}",
                            x_label=label, x=x,
                            series={key: np.asarray(residuals["after_0"], float)[ok]}))
    return out


def finding_rows(doc: dict) -> list[dict[str, str]]:
    """Display rows of the accepted findings (effect, location, parameters, evidence); the evidence's
    ``*_m`` figures in mm, or px where the document's residuals are px (a camera)."""
    rows = []
    ru = doc.get("residual_unit", "m")
    for f in doc.get("findings", []) or []:
        if not isinstance(f, dict):
            continue
        params = []
        for p in f.get("parameters", []) or []:
            if isinstance(p, dict):
                v, s, u = p.get("value"), p.get("std"), p.get("unit", "")
                ci = p.get("ci95")
                ok = isinstance(ci, list) and len(ci) == 2
                ci_txt = f", 95 % CI [{_fmt(ci[0], u)}, {_fmt(ci[1], u)}]" if ok else ""
                params.append(f"{p.get('name', '?')} = {_fmt(v, u)}" + (f" ± {_fmt(s, u)}" if s is not None else "")
                              + ci_txt)
        ev = f.get("evidence", {}) or {}
        rows.append({"effect": str(f.get("effect", f.get("name", "?"))), "location": _loc(f.get("location")),
                     "parameters": "; ".join(params),
                     "evidence": "; ".join(f"{k} = {_fmt(v, ru if k.endswith('_m') else '')}"
                                           for k, v in ev.items()) if isinstance(ev, dict) else str(ev),
                     "absorbed_fraction": _fmt(f.get("absorbed_fraction"), ""),
                     "confidence": str(f.get("confidence", "")) + (f" ({f['note']})" if f.get("note") else "")
                     + _alikes((f.get("look_alikes") or []) + (f.get("untested_look_alikes") or []))
                     + _runner_up(f.get("runner_up"))})
    return rows


def _alikes(v: Any) -> str:
    """'; the campaign can hardly tell it from X (Δχ² …)' for a finding's look-alikes."""
    items = [a for a in v or [] if isinstance(a, dict)]
    if not items:
        return ""
    return "; the campaign can hardly tell it from " + ", ".join(
        f"{a.get('effect')}@{a.get('location')} (" + (f"Δχ² {_fmt(a.get('delta_chi2'), '')}" if "delta_chi2" in a
                                                      else "not testable here") + ")" for a in items)


def _runner_up(v: Any) -> str:
    """'; runner-up X (Δχ² …)': the next name for a joint finding and how much worse its swap fits."""
    if not isinstance(v, dict):
        return ""
    return f"; runner-up {v.get('effect')}@{v.get('location')} (Δχ² {_fmt(v.get('delta_chi2'), '')})"


def _loc(v: Any) -> str:
    if isinstance(v, dict):
        return ", ".join(f"{k}: {x}" for k, x in v.items())
    return "" if v is None else str(v)


def _fmt(v: Any, unit: str) -> str:
    if v is None:
        return "–"
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        if unit == "m":
            return f"{v * 1e3:.4g} mm"
        if unit == "rad":
            return f"{np.degrees(v):.4g} deg"
        return f"{v:.4g}" + (f" {unit}" if unit else "")
    if isinstance(v, list):
        return "[" + ", ".join(_fmt(x, unit) for x in v) + "]"
    return str(v)
