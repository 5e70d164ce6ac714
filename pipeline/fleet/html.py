"""fleet.html: one self-contained page (inline CSS and SVG, no script, no external resource) for an
archive's reprocess results: per robot, each parameter and the accuracy over time with σ bands, the
flags (steps, trends, tolerance) and the failed or insufficient recordings."""

from __future__ import annotations

from datetime import datetime, timezone
from html import escape

from pipeline import __version__
from pipeline.fleet import plots
from pipeline.fleet.history import RobotHistory
from pipeline.report.labels import residual_text

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:1.5em auto;max-width:1100px;
color:#222;line-height:1.35}
h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}
table{border-collapse:collapse;margin:.5em 0;font-size:.9em}td,th{border:1px solid #ddd;padding:.25em .5em;
text-align:left}th{background:#f4f4f4}td.n{text-align:right;font-variant-numeric:tabular-nums}
.flag{color:#b00020;font-weight:600}.ok{color:#2e7d32;font-weight:600}.warn{color:#a15c00;font-weight:600}
figure{margin:.6em 0}figure svg{max-width:100%;height:auto}.note{color:#555;font-size:.9em}
"""


def day(t_ns: int | None) -> str:
    if t_ns is None:
        return "—"
    return datetime.fromtimestamp(t_ns / 1e9, tz=timezone.utc).strftime("%Y-%m-%d")


def _val(v: float, unit: str, digits: int = 4) -> str:
    k, u = plots.display(unit)
    return f"{v * k:.{digits}f} {u}"


def _rid(robot_id: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in robot_id)


def _verdict(h: RobotHistory) -> str:
    parts = []
    if h.steps:
        parts.append(f'<span class="flag">{len(h.steps)} step(s)</span>')
    if h.trends:
        parts.append(f'<span class="flag">{len(h.trends)} trend(s)</span>')
    if h.tolerance:
        parts.append(f'<span class="flag">{len(h.tolerance)} above tolerance</span>')
    if h.failed or h.insufficient:
        parts.append(f'<span class="warn">{len(h.failed)} failed, {len(h.insufficient)} insufficient</span>')
    return ", ".join(parts) or '<span class="ok">no flags</span>'


def overview(hs: list[RobotHistory]) -> str:
    rows = "".join(
        f'<tr><td><a href="#robot-{_rid(h.robot_id)}"><code>{escape(h.robot_id)}</code></a></td>'
        f'<td class="n">{len(h.usable)} / {len(h.rows)}</td>'
        f'<td>{day(h.usable[0]["campaign_start_ns"]) if h.usable else "—"} → '
        f'{day(h.usable[-1]["campaign_start_ns"]) if h.usable else "—"}</td>'
        f'<td class="n">{len(h.steps)}</td><td class="n">{len(h.trends)}</td><td class="n">{len(h.tolerance)}</td>'
        f'<td class="n">{len(h.failed)}</td><td class="n">{len(h.insufficient)}</td><td>{_verdict(h)}</td></tr>'
        for h in hs)
    return ('<section id="overview"><h2>Fleet overview</h2><table><tr><th>robot</th><th>calibrations used / all</th>'
            '<th>period</th><th>steps</th><th>trends</th><th>above tolerance</th><th>failed</th><th>insufficient</th>'
            f'<th>verdict</th></tr>{rows}</table></section>')


def robot_section(h: RobotHistory, tolerance_m: float | None) -> str:
    rid = _rid(h.robot_id)
    out = [f'<section id="robot-{rid}" class="robot" data-robot="{escape(h.robot_id)}" '
           f'data-steps="{len(h.steps)}" data-trends="{len(h.trends)}" data-tolerance="{len(h.tolerance)}">',
           f"<h2>Robot <code>{escape(h.robot_id)}</code> — {_verdict(h)}</h2>"]
    if h.steps:
        out.append('<h3>Steps between consecutive calibrations</h3><table class="steps"><tr><th>parameter</th>'
                   '<th>from</th><th>to</th><th>change</th><th>σ of the change</th><th>|z|</th><th>threshold</th>'
                   '<th>recording</th></tr>')
        for s in h.steps:
            out.append(f'<tr class="step" data-param="{escape(s["param"])}" data-date="{day(s["t_ns"])}">'
                       f'<td><code>{escape(s["param"])}</code>{_changed(s)}</td><td>{day(s["from_t_ns"])}</td>'
                       f'<td>{day(s["t_ns"])}</td><td class="n">{_val(s["delta"], s["unit"])}</td>'
                       f'<td class="n">{_val(s["sigma"], s["unit"])}</td><td class="n">{abs(s["z"]):.1f}</td>'
                       f'<td class="n">{s["threshold"]:.2f}</td><td><code>{escape(s["recording"])}</code></td></tr>')
        out.append("</table>")
    if h.free_set_changes:
        out.append('<h3>Identified parameters changed</h3><p class="note">The calibration fitted a different set of '
                   "parameters than the one before (news about the campaign, not a step of the robot): the others may "
                   "absorb what a held parameter no longer explains, so a move across the change is a step only when "
                   "calibrations with the same identified set before and after it disagree; the moves that could not "
                   "be confirmed are listed here."
                   '</p><table class="free-set"><tr>'
                   "<th>from</th><th>to</th><th>newly fitted</th><th>no longer fitted</th><th>moved, not confirmed</th>"
                   "<th>recording</th></tr>")
        for c in h.free_set_changes:
            out.append(f'<tr class="free-set-change" data-date="{day(c["t_ns"])}"><td>{day(c["from_t_ns"])}</td>'
                       f'<td>{day(c["t_ns"])}</td><td>{escape(", ".join(c["freed"]) or "—")}</td>'
                       f'<td>{escape(", ".join(c["held"]) or "—")}</td><td>{_moved(c)}</td>'
                       f'<td><code>{escape(c["recording"])}</code></td></tr>')
        out.append("</table>")
    if h.trends:
        out.append('<h3>Trends (drift)</h3><table class="trends"><tr><th>parameter</th><th>slope per year</th>'
                   '<th>σ</th><th>|z|</th><th>threshold</th><th>χ²/dof</th></tr>')
        for t in h.trends:
            out.append(f'<tr class="trend" data-param="{escape(t["param"])}"><td><code>{escape(t["param"])}</code>'
                       f'</td><td class="n">{_val(t["slope_per_year"], t["unit"])}</td>'
                       f'<td class="n">{_val(t["se_per_year"], t["unit"])}</td><td class="n">{abs(t["z"]):.1f}</td>'
                       f'<td class="n">{t["threshold"]:.2f}</td><td class="n">{t["chi2_dof"]:.2f}</td></tr>')
        out.append("</table>")
    if h.tolerance:
        out.append('<h3>Accuracy above the tolerance</h3><table class="tolerance"><tr><th>date</th>'
                   '<th>held-out RMS</th><th>recording</th></tr>')
        for t in h.tolerance:
            out.append(f'<tr class="over"><td>{day(t["t_ns"])}</td><td class="n">{residual_text(t["holdout_rms_m"], "m")}'
                       f'</td><td><code>{escape(t["recording"])}</code></td></tr>')
        out.append("</table>")
    out.append(f'<h3>Accuracy over time</h3><figure id="fig-accuracy-{rid}" class="plot">'
               f'{plots.accuracy(h, tolerance_m)}</figure>')
    svg = plots.parameters(h)
    if svg:
        out.append(f'<h3>Parameters over time</h3><p class="note">Change since the first calibration; bands ±1σ '
                   f'(dark) and ±3σ (light); red: a flagged step (vertical line) or trend (dashed fit).</p>'
                   f'<figure id="fig-params-{rid}" class="plot">{svg}</figure>')
    out.append("</section>")
    return "\n".join(out)


def problems(hs: list[RobotHistory]) -> str:
    rows = []
    for h in hs:
        for r in h.failed:
            rows.append(f'<tr class="failed"><td><code>{escape(h.robot_id)}</code></td><td>{day(r.get("campaign_start_ns"))}'
                        f'</td><td><code>{escape(r["recording"])}</code></td><td class="flag">{escape(str(r["status"]))}'
                        f'</td><td>{escape(str(r.get("error") or ""))}</td></tr>')
        for r in h.insufficient:
            rows.append(f'<tr class="insufficient"><td><code>{escape(h.robot_id)}</code></td>'
                        f'<td>{day(r.get("campaign_start_ns"))}</td><td><code>{escape(r["recording"])}</code></td>'
                        f'<td class="warn">insufficient</td><td>{escape(r["reason"])}</td></tr>')
    body = ("<table><tr><th>robot</th><th>date</th><th>recording</th><th>status</th><th>reason</th></tr>"
            + "".join(rows) + "</table>") if rows else '<p class="ok">none</p>'
    return f'<section id="problems"><h2>Failed or insufficient recordings</h2>{body}</section>'


def render(hs: list[RobotHistory], source: str, tolerance_m: float | None, alpha: float) -> str:
    n = sum(len(h.rows) for h in hs)
    tol = f"{tolerance_m * 1e3:g} mm held-out RMS" if tolerance_m is not None else "none stated (--tolerance-m)"
    method = (f'<section id="method"><h2>Method</h2><p class="note">Steps: a parameter that moved more than '
              f'c·σ between consecutive calibrations, c = max(3, Student t at α/(2m)) — family α = {alpha:g} per robot '
              f'over its m comparisons, t with the Welch–Satterthwaite degrees of freedom of the two σ; across a '
              f'change of the identified set, only when calibrations of one same set before and after confirm it. '
              f'Trends: '
              f'weighted least squares on time (one level per segment between flagged steps), slope σ scaled by '
              f'√(χ²/dof) when above 1, t test at α/(2P) over the robot\'s P parameters. Tolerance: {escape(tol)}. '
              f'Source: <code>{escape(source)}</code> ({n} recordings); robocal {__version__}.</p></section>')
    head = (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
            f'<meta name="generator" content="robocal/{__version__}"><title>robocal fleet — {escape(source)}'
            f'</title><style>{CSS}</style></head><body><h1>Fleet calibration history</h1>')
    parts = [head, overview(hs), problems(hs)] + [robot_section(h, tolerance_m) for h in hs] + [method,
                                                                                              "</body></html>"]
    return "\n".join(parts) + "\n"


def counts(hs: list[RobotHistory]) -> dict:
    """Machine-readable flags (fleet.json beside the page): {"generator", "robots": {robot id: flags}}."""
    from pipeline.recording.output import GENERATOR

    return {"generator": GENERATOR, "robots": {h.robot_id: {"calibrations": len(h.rows), "usable": len(h.usable),
                         "steps": [{k: s[k] for k in ("param", "t_ns", "recording", "delta", "sigma", "z", "threshold",
                                                      "free_set_change", "confirmed_by") if k in s} for s in h.steps],
                         "trends": [{k: t[k] for k in ("param", "slope_per_year", "se_per_year", "z", "threshold")}
                                    for t in h.trends],
                         "tolerance": h.tolerance,
                         "free_set_changes": h.free_set_changes,
                         "failed": [{"recording": r["recording"], "status": r["status"], "error": r.get("error")}
                                    for r in h.failed],
                         "insufficient": [{"recording": r["recording"], "reason": r["reason"]}
                                          for r in h.insufficient]}
                                  for h in hs}}


def _moved(change: dict) -> str:
    """The unconfirmed moves across a change of the identified set: parameter (|z|)."""
    return escape(", ".join(f'{m["param"]} (|z| {abs(m["z"]):.1f})' for m in change.get("moved") or [])) or "—"


def _changed(step: dict) -> str:
    """The mark of a step found across a change of the identified set."""
    c = step.get("free_set_change")
    if not c:
        return ""
    what = "; ".join(x for x in (("fitted " + ", ".join(c["freed"])) if c["freed"] else "",
                                 ("held " + ", ".join(c["held"])) if c["held"] else "") if x)
    return f' <span class="note">(identified set changed: {escape(what)})</span>'

