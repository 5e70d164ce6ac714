"""The report's Physics section: geometry-only against with-physics held-out error and each kept
term (value, 1σ, stiffness; reading errors: value, 1σ, unit) — the calibrated model's physics in one place
(identify/fit.json `physics`), and the families the data could not carry (backlash without a motion direction)."""

from __future__ import annotations

from html import escape

from pipeline.report.markup import section, table


def section_html(fit: dict) -> str:
    """'' when the model has no physics terms."""
    doc = fit.get("physics")
    if not doc:
        return ""
    g, w = doc["holdout_geometry_only_m"] * 1e3, doc["holdout_with_physics_m"] * 1e3
    html = table(["model", "held-out RMS"], [["geometry only (physics held at 0)", f"{g:.4f} mm"],
                                            ["with the kept physics terms", f"{w:.4f} mm"]], {1})
    gravity = [t for t in doc["terms"] if "compliance_rad_per_Nm" in t]
    reading = [t for t in doc["terms"] if "compliance_rad_per_Nm" not in t]
    if gravity:
        rows = [[f"<code>{escape(t['joint'])}</code>", escape(t["family"]), escape(t["axis"]),
                 f"{t['compliance_rad_per_Nm']:.4g}",
                 "–" if t["compliance_std_rad_per_Nm"] is None else f"{t['compliance_std_rad_per_Nm']:.2g}",
                 "–" if t["stiffness_Nm_per_rad"] is None else f"{t['stiffness_Nm_per_rad']:.4g}",
                 "–" if t["relative_std"] is None else f"{100 * t['relative_std']:.0f} %"] for t in gravity]
        html += table(["joint", "family", "axis", "compliance rad/(N·m)", "σ", "stiffness N·m/rad", "rel. σ"], rows,
                      {3, 4, 5, 6})
    if reading:
        rows = [[f"<code>{escape(t['joint'])}</code>", escape(t["family"]), escape(t["term"]), f"{t['value']:.4g}",
                 "–" if t["std"] is None else f"{t['std']:.2g}", escape(t["unit"])] for t in reading]
        html += table(["joint", "family", "term", "value", "σ", "unit"], rows, {3, 4})
    if doc["terms"]:
        html += "<ul>" + "".join(f"<li>{escape(t['reading'])}</li>" for t in doc["terms"]) + "</ul>"
    else:
        html += (f'<p>No physics term lowered the held-out error: the model stays rigid (offered: '
                 f"{escape(', '.join(doc['offered']) or 'none')}).</p>")
    for n in doc.get("not_fitted", []):
        html += f"<p>{escape(n['reason'])}.</p>"
    payload = ", ".join(f"{p['mass_kg']:g} kg at {p['link']}" for p in doc.get("payload", [])) or "none"
    html += (f'<p class="note">Gravity loads from the URDF inertials by Pinocchio (whole tree); payload: '
             f"{escape(payload)}; equilibrium: {escape(doc['equilibrium'])}. Terms are kept only when they lower "
             "the held-out error (model selection). The sidecar model.physics.yaml carries them beside model.urdf.</p>")
    return section("physics", "Physics", html)
