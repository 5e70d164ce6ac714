"""report.html: one self-contained page (inline CSS and SVG, no script, no network).

`render` is pure: run artefacts (+ version and parameters) in, an HTML string out.
"""

from __future__ import annotations

from pipeline import __version__

from html import escape
from typing import Any

import numpy as np

from pipeline.report import compensation
from pipeline.report import diagnosis as dg
from pipeline.report import figures as fg
from pipeline.report import plots
from pipeline.report.labels import joints_unit_phrase, residual_display, residual_text
from pipeline.report.markup import figure as _figure
from pipeline.report.markup import section as _section
from pipeline.report.markup import table as _table

CSS = """
:root { --ink:#1d2330; --muted:#5b6475; --line:#dde1e8; --bg:#f6f7f9; --ok:#2e7d32; --warn:#b26a00; --fail:#c62828; }
* { box-sizing: border-box; }
body { margin:0; font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif; color:var(--ink); background:var(--bg); }
header { background:#1d2330; color:#fff; padding:18px 32px; }
header h1 { margin:0; font-size:22px; font-weight:600; }
header p { margin:4px 0 0; color:#c5cad6; }
nav { padding:8px 32px; background:#fff; border-bottom:1px solid var(--line); position:sticky; top:0; }
nav a { margin-right:14px; color:#33508a; text-decoration:none; font-size:13px; }
main { max-width:1180px; margin:0 auto; padding:8px 32px 48px; }
section { background:#fff; border:1px solid var(--line); border-radius:8px; padding:16px 20px; margin:18px 0; }
h2 { margin:0 0 10px; font-size:18px; }
h3 { margin:16px 0 6px; font-size:15px; }
.cards { display:grid; grid-template-columns:repeat(auto-fill,minmax(170px,1fr)); gap:10px; }
.card { border:1px solid var(--line); border-radius:6px; padding:10px 12px; }
.card .v { font-size:20px; font-weight:600; }
.card .k { color:var(--muted); font-size:12px; }
table { border-collapse:collapse; width:100%; font-size:13px; }
th, td { border-bottom:1px solid var(--line); padding:4px 8px; text-align:left; vertical-align:top; }
th { background:#f0f2f5; font-weight:600; }
td.n { text-align:right; font-variant-numeric:tabular-nums; white-space:nowrap; }
tr.fixed td { color:var(--muted); }
.badge { display:inline-block; padding:1px 8px; border-radius:10px; font-size:12px; color:#fff; }
.pass { background:var(--ok); } .warn { background:var(--warn); } .fail { background:var(--fail); }
figure { margin:10px 0 16px; } figure svg { max-width:100%; height:auto; }
figcaption { color:var(--muted); font-size:12px; }
code { background:#f0f2f5; padding:1px 4px; border-radius:3px; font-size:12px; }
.note { color:var(--muted); font-size:12px; }
ul.warnings li { color:var(--warn); }
"""


def _mm(v: float | None, digits: int = 4) -> str:
    return "–" if v is None else f"{v * 1e3:.{digits}f} mm"


def _num(v: float | None, digits: int = 4) -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "–"
    return f"{v:.{digits}f}"


def _sig(v: float | None, digits: int = 5) -> str:
    """4 decimals in the usual range; significant figures outside it (a pixel pitch of 6.6e-06 m/px or a
    σ of 4e-05 mm stays readable instead of printing 0.0000)."""
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "–"
    if v == 0 or 1e-3 <= abs(v) < 1e6:
        return f"{v:.4f}"
    return f"{v:.{digits}g}"


def summary_section(s: dict[str, Any], warnings: list[str]) -> str:
    res = lambda v: residual_text(v, s.get("residual_unit"))  # noqa: E731 — mm, or px for a camera
    cards = [("RMS before", res(s["rms_before_m"])), ("RMS after", res(s["rms_after_m"])),
             ("held-out RMS", res(s["holdout_rms_m"])),
             ("parameters identified", f"{s['n_identifiable']} / {s['n_parameters']}"),
             ("measurements", f"{s['n_measurements']}" + (f" ({s['n_rejected']} rejected)" if s["n_rejected"] else "")),
             ("max |residual| after", res(s["max_abs_after_m"]))]
    if s.get("rms_3d_after_m") is not None:  # URDF points / poses: the norm of the 3-D error, as other tools publish
        cards[:3] = [(f"{k} (per axis)", v) for k, v in cards[:3]]
        cards[:0] = [("RMS of the 3-D error before → after",
                      f"{_mm(s.get('rms_3d_before_m'))} → {_mm(s['rms_3d_after_m'])}"),
                     ("held-out RMS of the 3-D error (k-fold, within this recording)", _mm(s.get("holdout_rms_3d_m")))]
    if s.get("accuracy_map_rms_1sigma_m") is not None:  # the one stated accuracy: the map's (accuracy section)
        cards.append(("predicted accuracy over the workspace (1σ RMS)", _mm(s["accuracy_map_rms_1sigma_m"])))
    if s.get("sigma_m") is not None:
        cards.append(("residual σ", res(s["sigma_m"])))
    html = '<div class="cards">' + "".join(
        f'<div class="card"><div class="v">{escape(v)}</div><div class="k">{escape(k)}</div></div>' for k, v in cards
    ) + "</div>"
    html += (f'<p class="note">System <b>{escape(s["system"])}</b>; loss <code>{escape(str(s["loss"]))}</code>; '
             f'{s["solver_evaluations"]} solver evaluations. Held-out: each measurement predicted by a fit without it '
             f"(cross-validation).</p>")
    corr = s.get("correction")
    if isinstance(corr, dict) and not corr.get("applied", True):  # the nominal robot kept: said first, with why
        tried = "".join(f"<li>{escape(str(t['candidate']))}: held-out {_mm(t.get('holdout_rms_m'))}"
                        + (f" — {escape(str(t['reason']))}" if t.get("reason") else "") + "</li>"
                        for t in corr.get("tried", []))
        html = (f'<p class="correction" id="no-correction"><b>No correction applied</b>: the nominal robot was kept '
                f'(registration only). {escape(str(corr.get("reason", "")))}</p>'
                + (f'<ul class="tried">{tried}</ul>' if tried else "")) + html
    if warnings:
        html += "<h3>Warnings</h3><ul class=\"warnings\">" + "".join(f"<li>{escape(w)}</li>" for w in warnings) + "</ul>"
    return _section("summary", "Summary", html)


def residual_section(art, series: fg.ResidualSeries) -> str:
    ru = series.unit
    res = lambda v: residual_text(v, "px" if ru == "px" else None)  # noqa: E731
    rows = [[escape(r["group"]), str(r["n"]), res(r["rms_before_m"]), res(r["rms_after_m"]),
             res(r["rms_holdout_m"])] for r in fg.group_table(art)]
    html = _table([series.group_title, "n", "RMS before", "RMS after", "RMS held out"], rows, {1, 2, 3, 4})
    html += _figure(plots.residuals_by_group(series), f"Residuals per {series.group_title.replace(' / ', '/')} "
                    "before and after calibration "
                    f"({ru}); held out = predicted by a fit that did not see the measurement.", "fig-residuals-group")
    against = ("time since the first measurement" if series.time_label.startswith("time")
               else "the measurement's row in the table (it has no times)")
    html += _figure(plots.residuals_vs_time(series), f"Residuals against {against} ({ru}): "
                    "structure here means drift.", "fig-residuals-time")
    if series.joints:
        unit = joints_unit_phrase(series.joints, series.prismatic)
        html += _figure(plots.residuals_vs_joints(series), "Residuals after calibration against each joint angle "
                        f"({ru} vs {unit}): structure here means an effect the model leaves out.", "fig-residuals-joints")
    return _section("residuals", "Residuals", html)


def parameter_section(fit: dict) -> str:
    rows = fg.parameter_rows(fit)
    iid = fit.get("std_independent") is not None  # the stated σ is a resampling σ (a camera: image jackknife)
    body = [[f"<code>{escape(r['name'])}</code>", escape(r["unit"]), _sig(r["nominal"]), _sig(r["estimate"]),
             _sig(r["change"]), _sig(r["std"])] + ([_sig(r["std_independent"])] if iid else []) +
            ["yes" if r["free"] else "fixed", escape(r["reason"])] for r in rows]
    how = (f"by the {escape(str(fit.get('std_kind', 'resampling')))}; σ independent: what σ²·(JᵀJ)⁻¹ would state, "
           "too small where measurements share errors" if iid else "from the covariance (residual σ²·(JᵀJ)⁻¹)")
    html = (f'<p class="note">Lengths in mm, angles in deg. σ: 1σ standard deviation {how}. '
            "Fixed parameters stay at their nominal value; the reason says why.</p>")
    heads = ["parameter", "unit", "nominal", "estimate", "change", "σ"] + (["σ independent"] if iid else [])
    html += _table(heads + ["identified", "reason"], body, {2, 3, 4, 5} | ({6} if iid else set()),
                   row_class=lambda i: "" if rows[i]["free"] else "fixed")
    return _section("parameters", "Parameters", html)


def observability_section(art) -> str:
    html = ""
    obs = art.observe or {}
    s = fg.singular_values(art)
    idx = [(k, obs[k]) for k in ("O1", "O2", "O3", "O4", "O5") if k in obs]
    if idx:
        html += _table(["index", "value"], [[k, f"{v:.4g}"] for k, v in idx], {1})
    if s is not None and s.size:
        html += _figure(plots.singular_values(s), "Singular values of the column-scaled identification Jacobian: "
                        "a small last value means a weakly observed combination.", "fig-singular")
    deps = obs.get("dependencies") or {}
    if deps:
        html += "<h3>Dependent (not identifiable) combinations</h3>" + _table(
            ["parameter", "combination"], [[f"<code>{escape(str(k))}</code>", escape(str(v))] for k, v in deps.items()])
    c = fg.correlation(art)
    if c is not None:
        names, mat = c
        html += _figure(plots.correlation(names, mat), "Correlation matrix of the identified parameters.",
                        "fig-correlation")
        top = fg.strongest_correlations(names, mat)
        html += "<h3>Strongest correlations</h3>" + _table(
            ["parameter", "parameter", "correlation"],
            [[f"<code>{escape(a)}</code>", f"<code>{escape(b)}</code>", f"{v:+.3f}"] for a, b, v in top], {2})
    if not html:
        html = '<p class="note">The observe stage has not run for this directory.</p>'
    return _section("observability", "Observability", html)


def solver_section(history: list[float]) -> str:
    if not history:
        return _section("solver", "Solver", '<p class="note">No solver history recorded.</p>')
    return _section("solver", "Solver", _figure(plots.solver_history(history), "RMS residual at each evaluation "
                                                "of the nonlinear least-squares solver (mm).", "fig-solver"))


def validation_section(val: dict | None) -> str:
    if not val:
        return _section("validation", "Validation", '<p class="note">The validate stage has not run.</p>')
    rows = []
    for ch in val.get("checks", []):
        st = str(ch.get("status", "?"))
        recs = ch.get("records", []) or []
        shown = ", ".join(str(r) for r in recs[:20]) + (f" … ({len(recs)} in all)" if len(recs) > 20 else "")
        rows.append([escape(str(ch.get("name", "?"))), f'<span class="badge {escape(st)}">{escape(st)}</span>',
                     escape(str(ch.get("message", ""))), escape(shown)])
    return _section("validation", "Validation", _table(["check", "status", "message", "records"], rows))


def unseen_table(doc: dict) -> str:
    """Every effect looked for, the size it could have had unseen on this campaign and what would reveal it
    (`diagnose.document.unseen`), whatever the status."""
    es = [e for e in doc.get("unseen") or [] if isinstance(e, dict)]
    if not es:
        return ""
    return ("<h3>What this campaign could not have seen</h3>"
            f'<p class="note">Each effect looked for and the largest size it could have had here and gone unseen '
            f"(found with {float(es[0].get('power', 0.8)):.0%} probability at that size); a status of clean means no "
            "effect above these sizes.</p>"
            + _table(["effect", "location", "could have gone unseen", "what would reveal it"],
                     [[escape(str(e.get("effect"))), escape(str(e.get("location"))),
                       escape("found" if e.get("found") else str(e.get("display"))), escape(str(e.get("reveal")))]
                      for e in es]))


def diagnosis_section(art) -> str:
    doc = art.diagnosis
    if not isinstance(doc, dict):
        return ""
    html = ""
    if isinstance(doc.get("status"), str):  # the diagnosis' verdict, outlier records, findings not reported
        html += (f'<p class="note">Status: <b>{escape(doc["status"].replace("_", " "))}</b> — '
                 f'{escape(str(doc.get("status_reason", "")))}</p>')
        for o in [o for o in doc.get("outlier_records") or [] if isinstance(o, dict)]:
            html += f'<p class="note">Outlier record {escape(str(o.get("record")))}: {escape(str(o.get("reason")))}</p>'
        for f in [f for f in doc.get("rejected_findings") or [] if isinstance(f, dict)]:
            html += (f'<p class="note">Not reported as found: {escape(str(f.get("effect")))}@'
                     f'{escape(str(f.get("location")))} — {escape(str(f.get("note")))}</p>')
    rows = dg.finding_rows(doc)
    if rows:
        html += "<h3>Findings</h3>" + _table(
            ["effect", "location", "parameters", "evidence", "absorbed fraction", "confidence"],
            [[escape(r[k]) for k in ("effect", "location", "parameters", "evidence", "absorbed_fraction",
                                     "confidence")] for r in rows])
    else:
        html += '<p class="note">No finding: no left-out effect was detected.</p>'
    dropped = [d for d in (doc.get("clustered_inference") or {}).get("dropped_by_check") or [] if isinstance(d, dict)]
    if dropped:
        html += ('<p class="note">Accepted by the F tests but not confirmed by the pose sign-flip check (so not '
                 "reported as findings): " + escape(", ".join(f"{d.get('effect')}@{d.get('location')}" for d in dropped))
                 + "</p>")
    b, a = doc.get("holdout_rms_before_m"), doc.get("holdout_rms_after_m")
    k, ru = residual_display(doc.get("residual_unit"))  # mm, or px for a camera
    unit = "posture" if art.system == "urdf" else "jig face / pose"  # what the diagnosis's folds keep together
    if isinstance(b, (int, float)) and not rows:
        html += (f'<p class="note">Held-out RMS of the geometric model in the diagnosis\'s own cross-validation: '
                 f"{b * k:.4f} {ru} (its folds keep each {unit} together, so it differs from the summary's "
                 "k-fold figure).</p>")
    elif isinstance(b, (int, float)) and isinstance(a, (int, float)):
        html += _figure(plots.bars(["before", "after"], [b * k, a * k], f"held-out RMS ({ru})",
                                   "held-out RMS: geometry only vs with the findings"),
                        f"Held-out RMS before {b * k:.4f} {ru}, after modelling the findings {a * k:.4f} {ru} "
                        f"(the diagnosis's own cross-validation, folds grouped by {unit.removeprefix('jig ')}: it "
                        "differs from the "
                        "summary's k-fold figure).",
                        "fig-diagnosis-improvement")
    cols = None
    if art.measurements is not None:
        cols = {k: v for k, v in art.measurements.items() if np.ndim(v) == 1}
        cols.update({f"q_{n}": v for n, v in art.joint_columns().items()})
    specs = dg.find_plots(doc) or dg.located_plots(doc, cols, art.residuals, art.prismatic_joints())
    for i, p in enumerate(specs):
        scale = 1e3 if p.lengths else 1.0
        series = {k[:-2] if k.endswith("_m") else k: v for k, v in p.series.items()}
        y_label = p.y_label or ("residual (m)" if p.lengths else "value")
        if p.lengths:  # drawn in mm
            y_label = y_label.replace("(m)", "(mm)") if "(m)" in y_label else f"{y_label} (mm)"
        html += _figure(plots.xy_series(p.x, series, p.x_label, y_label, p.title, y_scale=scale), p.title,
                        f"fig-diagnosis-{i}")
    ni = doc.get("not_identifiable") or []
    if ni:
        html += "<h3>Not identifiable with this campaign</h3>" + _table(
            ["effect", "location", "absorbed by", "what to change"],
            [[escape(str(e.get("effect", "?"))), escape(dg._loc(e.get("location", ""))),
              escape(str(e.get("absorbed_by", e.get("absorbs", "")))),
              escape(str(e.get("advice", e.get("remedy", ""))))] for e in ni if isinstance(e, dict)])
    html += unseen_table(doc)
    un = doc.get("unexplained")
    where = [w for w in doc.get("unexplained_where", []) or [] if isinstance(w, dict)]
    if un not in (None, False, {}) or where:
        html += "<h3>Unexplained structure</h3>"
        if where:
            html += _table(["variable", "region", "p-value", "peak"],
                           [[escape(str(w.get("variable", ""))), escape(dg._fmt(w.get("region"), "")),
                             escape(dg._fmt(w.get("p_value"), "")), escape(dg._fmt(w.get("peak_m"), "m"))]
                            for w in where], {2, 3})
        else:
            html += f"<p>{escape(dg._loc(un)) if not isinstance(un, bool) else 'yes'}</p>"
    elif un is False:
        html += '<p class="note">No structure left in the residuals (lack-of-fit tests).</p>'
    lof = [t for t in doc.get("lack_of_fit", []) or [] if isinstance(t, dict)]
    if lof:
        raw = any(isinstance(t.get("p_value_raw"), (int, float)) for t in lof)  # the column only where there are values
        html += "<h3>Lack-of-fit tests</h3>" + _table(
            ["variable", "statistic", "p-value (Holm)"] + (["p-value (raw)"] if raw else []),
            [[escape(str(t.get("variable", ""))), escape(dg._fmt(t.get("statistic"), "")), _p(t.get("p_value"))]
             + ([_p(t.get("p_value_raw"))] if raw else []) for t in lof], {1, 2, 3}) + (
            '<p class="note">Holm-adjusted p-values are capped at 1 (three significant figures below it): 1 means '
            "no evidence of structure against that variable.</p>")
    return _section("diagnosis", "Diagnosis", html)


def _p(v: Any) -> str:
    """A p-value with 3 significant figures (Holm-adjusted values are capped at 1: shown as 1, not rounded to it)."""
    if not isinstance(v, (int, float)) or not np.isfinite(v):
        return "–"
    return "1" if v >= 1 else f"{v:.3g}"


def provenance_section(prov: dict[str, Any], rrd_name: str | None) -> str:
    rows = [["input file", escape(str(prov.get("input_path") or "–"))],
            ["input sha256", f"<code>{escape(str(prov.get('input_sha256') or '–'))}</code>"],
            ["robocal version", escape(prov["robocal_version"])]]
    rows += [[f"metadata: {escape(k)}", escape(str(v))] for k, v in prov.get("metadata", {}).items()]
    html = _table(["item", "value"], rows)
    st = [[escape(s), f"<code>{escape(str(d.get('key') or ''))}</code>",
           f"<code>{escape(_json(d.get('params', {})))}</code>",
           escape(str(d.get("robocal_version") or ""))] for s, d in prov.get("stages", {}).items()]
    st.append(["report", "", f"<code>{escape(_json(prov.get('report_params', {})))}</code>", ""])
    html += "<h3>Stages</h3>" + _table(["stage", "key", "parameters", "version"], st)
    if rrd_name:
        html += (f'<p class="note">3-D view of this run: <code>{escape(rrd_name)}</code> beside this file; open it '
                 f"with <code>robocal view DIR</code> (rerun viewer).</p>")
    return _section("provenance", "Provenance", html)


def _json(v: Any) -> str:
    import json

    return json.dumps(v, sort_keys=True, default=str)


def render(art, version: str, params: dict[str, Any], rrd_name: str | None = "run.rrd", tick=None) -> str:
    """The whole report page; `tick(note)` is called after each section (progress)."""
    tick = tick or (lambda note="": None)
    s = fg.summary(art)
    if art.fit.get("residual_unit"):  # a camera's residuals: px
        s["residual_unit"] = art.fit["residual_unit"]
    if art.fit.get("correction"):  # the nominal robot kept (`pipeline.identify.correction`)
        s["correction"] = art.fit["correction"]
    if isinstance(art.accuracy, dict) and art.accuracy.get("map_rms_1sigma_m") is not None:
        s["accuracy_map_rms_1sigma_m"] = art.accuracy["map_rms_1sigma_m"]
    series = fg.residual_series(art)
    prov = fg.provenance(art, version, params)
    warnings = list(prov["warnings"])
    if art.validate:
        warnings += [f"{c.get('name')}: {c.get('message')}" for c in art.validate.get("checks", [])
                     if c.get("status") == "warn"]
    from pipeline.report.accuracy import accuracy_section

    from pipeline.report.physics import section_html as physics_section

    from pipeline.report.camera import section as camera_section

    acc_html = accuracy_section(art)
    tick("accuracy section")
    phys_html = physics_section(art.fit)
    cam_html = camera_section(art)
    sections = [summary_section(s, warnings), acc_html]
    for name, make in (("residuals", lambda: residual_section(art, series) + cam_html), ("physics", lambda: phys_html),
                       ("parameters", lambda: parameter_section(art.fit)), ("observability", lambda: observability_section(art)),
                       ("solver", lambda: solver_section(art.history)), ("validation", lambda: validation_section(art.validate)),
                       ("diagnosis", lambda: diagnosis_section(art))):
        sections.append(make())
        tick(f"{name} section")
    comp = compensation.section(art.run_dir)
    sections += [comp or "", provenance_section(prov, rrd_name)]
    titles = [("summary", "Summary")] + ([("accuracy", "Accuracy")] if acc_html else []) + [
              ("residuals", "Residuals")] + ([("camera", "Camera images")] if cam_html else []) + (
              [("physics", "Physics")] if phys_html else []) + [("parameters", "Parameters"),
              ("observability", "Observability"), ("solver", "Solver"), ("validation", "Validation")]
    if art.diagnosis is not None:
        titles.append(("diagnosis", "Diagnosis"))
    if comp:
        titles.append(("compensation", "Compensation"))
    titles.append(("provenance", "Provenance"))
    nav = "".join(f'<a href="#{i}">{escape(t)}</a>' for i, t in titles)
    src = prov.get("input_path") or "recording"
    name = art.robot_name() if hasattr(art, "robot_name") else s["system"]
    name = s["system"] if name == s["system"] else f"{name} ({s['system']})"
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="generator" content="robocal/{__version__}">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>robocal report — {escape(name)}</title><style>{CSS}</style></head><body>"
            f"<header><h1>robocal calibration report — {escape(name)}</h1>"
            f"<p>{escape(str(src))} · robocal {escape(version)}</p></header><nav>{nav}</nav>"
            f"<main>{''.join(sections)}</main></body></html>\n")
