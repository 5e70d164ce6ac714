"""report.html of `robocal evaluate`: a calibration applied, without refitting, to recordings it never saw.

`render` is pure: the evaluation document (what evaluation.json holds) and the per-measurement error table
(what errors.parquet holds) in, one self-contained HTML page out (inline CSS and SVG, no script, no network).
"""

from __future__ import annotations

from html import escape
from pathlib import Path

import numpy as np

from pipeline import __version__
from pipeline.report import plots
from pipeline.report.html import CSS
from pipeline.report.markup import figure, section, table

POSTURES_NOTE = ("postures: each evaluated posture relative to the postures the calibration was fitted on — "
                 "repeated (every joint within 0.01 rad or m of one), new (inside the training range widened by "
                 "0.05 rad or m), out_of_range (some joint beyond it: extrapolation); point and pose data")


def _mm(v) -> str:
    return "—" if v is None else f"{v * 1e3:.3f}"


def _px(v) -> str:
    return "—" if v is None else f"{v:.3f}"


def _heads(measure: str) -> list[str]:
    if measure == "plane":
        return ["recording / group", "n", "RMS along the normal (mm)", "mean |d| (mm)", "max |d| (mm)"]
    if measure == "camera":
        return ["recording / image", "corners", "RMS of the 2-D reprojection error (px)", "mean 2-D (px)",
                "max 2-D (px)", "RMS per axis (px)"]
    heads = ["recording / group", "n", "RMS of the 3-D error (mm)", "mean 3-D (mm)", "max 3-D (mm)",
             "RMS per axis (mm)"]
    return heads + (["RMS rotation (mrad)"] if measure == "pose" else []) + (
        ["RMS socket-distance error (mm)"] if measure == "coincidence" else [])


def _row(name: str, d: dict, measure: str) -> list[str]:
    if measure == "plane":
        return [name, str(d.get("n", 0)), _mm(d.get("rms_normal_m")), _mm(d.get("mean_abs_normal_m")),
                _mm(d.get("max_abs_normal_m"))]
    if measure == "camera":
        return [name, str(d.get("n", 0))] + [_px(d.get(k)) for k in ("rms_2d_px", "mean_2d_px", "max_2d_px",
                                                                      "rms_axis_px")]
    cells = [name, str(d.get("n", 0)), _mm(d.get("rms_3d_m")), _mm(d.get("mean_3d_m")), _mm(d.get("max_3d_m")),
             _mm(d.get("rms_axis_m"))]
    if measure == "pose":
        cells.append(_mm(d.get("rms_rotation_rad")))
    if measure == "coincidence":
        cells.append(_mm(d.get("rms_distance_error_m")))
    return cells


def render(doc: dict, errors: dict[str, np.ndarray]) -> str:
    """The page of one evaluation (`doc`: evaluation.json's content; `errors`: errors.parquet's columns)."""
    recs = doc["recordings"]
    measure = recs[0]["measure"] if recs else "point"
    rows: list[list[str]] = []
    for r in recs:
        name = escape(Path(r["path"]).name)
        rows.append([f"<b>{name}</b>"] + _row("", r, measure)[1:])
        if len(r.get("groups", {})) > 1:
            rows += [_row(f"&nbsp;&nbsp;{escape(g)}", d, measure) for g, d in r["groups"].items()]
        rows += [_row(f"&nbsp;&nbsp;{escape(g.replace('_', ' '))} postures", d, measure)
                 for g, d in (r.get("postures") or {}).items()]
    heads = _heads(measure)
    refit = doc.get("refit", "none")
    head = (f"<p>The calibration of <code>{escape(str(doc.get('run', '')))}</code>, fitted on "
            f"<code>{escape(str(doc.get('calibrated_on', '')))}</code>, applied to {len(recs)} recording(s) "
            + ("<b>without refitting</b> (robot, instrument registration, tool and target offsets as fitted)."
               if refit == "none" else f"with the instrument registration re-estimated ({escape(str(doc.get('registration')))}), "
               "everything else as fitted.") + "</p>")
    notes = (f"<p class=\"note\">{escape(doc.get('note', ''))}.</p>"
             + (f"<p class=\"note\">{escape(POSTURES_NOTE)}.</p>" if any(r.get("postures") for r in recs) else ""))
    body = head + table(heads, rows, numeric=set(range(1, len(heads)))) + notes
    kind = errors.get("kind", np.zeros(0, int))
    m = np.asarray(kind) == 0
    if m.any():
        paths = np.asarray(errors["recording"], object)
        names = [Path(r["path"]).name for r in recs]
        norms = [np.asarray(errors["norm_m"], float)[m & (paths == r["path"])] for r in recs]
        kinds = [np.asarray(errors.get("posture", np.full(len(paths), "", object)), object)[m & (paths == r["path"])]
                 for r in recs]
        y = {"plane": "distance along the normal (mm)", "camera": "2-D reprojection error (px)"}.get(
            measure, "norm of the 3-D error (mm)")
        body += figure(plots.error_norms(names, norms, kinds, y, 1.0 if measure == "camera" else plots.MM),
                       "Every measurement's error, one column per "
                       "recording" + (", coloured by posture group" if any(k.any() for k in kinds) else ""),
                       "evaluation-errors")
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="generator" content="robocal/{__version__}">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>robocal evaluation</title><style>{CSS}</style></head><body>"
            f"<header><h1>robocal evaluation — on recordings the calibration never saw</h1>"
            f"<p>{escape(str(doc.get('run', '')))} · robocal {escape(__version__)}</p></header>"
            f"<main>{section('evaluation', 'Evaluation on other recordings', body)}</main></body></html>\n")
