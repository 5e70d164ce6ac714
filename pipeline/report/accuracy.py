"""Report sections on honest accuracy: the accuracy verdict and map, 3-D measurement coverage,
residual histograms against the noise floor, per-joint residuals before and after, the
scanner's image-plane residual field and the Delta's per-axis residuals.  Pure: artefacts in,
HTML (inline SVG) out."""

from __future__ import annotations

from html import escape

import numpy as np
from matplotlib import rc_context

from pipeline.report.artefacts import RunArtefacts, residual_matrix
from pipeline.report.plots import MM, RC, _fig, _svg, hist_bins

AXIS_RGB = ("#d62728", "#2ca02c", "#1f77b4")  # x, y, z


def _mm(v) -> str:
    return "–" if v is None else f"{float(v) * 1e3:.3g} mm"


JOINT_COLUMNS = 3  # joints a row in the per-joint figures (as `report.plots.residuals_vs_joints`)


def _fig_html(svg: str, caption: str, fig_id: str) -> str:
    return f'<figure id="{fig_id}" class="plot">{svg}<figcaption>{escape(caption)}</figcaption></figure>'


def map_and_coverage(points: np.ndarray, sigma: np.ndarray, measured: np.ndarray | None) -> str:
    """Static 3-D view: map points coloured by predicted 1σ (mm), measured points in black."""
    with rc_context(RC):
        fig, _ = _fig(6.4, 4.6)
        fig.clf()
        a = fig.add_subplot(projection="3d")
        sc = a.scatter(*(points * MM).T, c=sigma * MM, cmap="viridis", s=22, depthshade=False)
        if measured is not None and len(measured):
            a.scatter(*(measured * MM).T, c="k", s=6, marker="x", label="measured", depthshade=False)
            a.legend(loc="upper left")
        fig.colorbar(sc, ax=a, shrink=0.7, label="predicted 1σ (mm)")
        a.set_xlabel("x (mm)")
        a.set_ylabel("y (mm)")
        a.set_zlabel("z (mm)")
    return _svg(fig)


def histograms(before: np.ndarray, after: np.ndarray, floor_m: float | None, residual_unit: str | None = None) -> str:
    """Residual histograms before and after (separate axes: their scales differ by orders),
    with ±the noise floor (residual σ) marked; mm, a camera's px (`residual_unit`)."""
    from pipeline.report.labels import residual_display

    scale, mm = residual_display(residual_unit)
    with rc_context(RC):
        fig, ax = _fig(7.6, 2.8, 1, 2)
        for a, r, name, col in ((ax[0, 0], before, "before", "#d62728"), (ax[0, 1], after, "after", "#2ca02c")):
            r = np.asarray(r, float).ravel()
            r = r[np.isfinite(r)] * scale
            r, bins = hist_bins(r, 30)
            a.hist(r, bins=bins, color=col)
            if floor_m:
                for s in (-floor_m, floor_m):
                    a.axvline(s * scale, color="k", ls="--", lw=0.8)
            a.set_xlabel(f"residual {name} ({mm})")
            a.set_ylabel("residuals")
        if floor_m:
            ax[0, 1].set_title(f"dashed: ±noise floor σ = {floor_m * scale:.3g} {mm}", fontsize=9)
    return _svg(fig)


def joints_before_after(joints: dict[str, np.ndarray], before: np.ndarray, after: np.ndarray,
                        prismatic: frozenset = frozenset(), residual_unit: str | None = None) -> str:
    """|residual| against each joint angle (deg; a prismatic joint's travel mm), before (upper panel of
    each pair) and after (lower); of a pose, its position part; mm, a camera's px (`residual_unit`).
    Wrapped as the residuals section's per-joint figure: at most `JOINT_COLUMNS` joints a row, so a
    humanoid's 18 joints stay readable."""
    from pipeline.report.labels import joint_scale, residual_display

    rs, mm = residual_display(residual_unit)  # mm, a camera's px
    names = list(joints)
    ncols = JOINT_COLUMNS if len(names) > 4 else max(len(names), 1)
    nrows = max(int(np.ceil(len(names) / ncols)), 1)
    with rc_context(RC):
        fig, ax = _fig(min(2.4 * ncols, 9.5), 3.9 * nrows + 0.3, 2 * nrows, ncols)
        for j in range(nrows * ncols):
            pair = ax[2 * (j // ncols):2 * (j // ncols) + 2, j % ncols]
            if j >= len(names):
                for a in pair:
                    a.set_visible(False)
                continue
            n = names[j]
            scale, unit = joint_scale(n, prismatic)
            q = np.asarray(joints[n], float) * scale
            for row, (r, col) in enumerate(((before, "#d62728"), (after, "#2ca02c"))):
                a = pair[row]
                for k in range(min(r.shape[1], 3)):  # a pose's position part (its rotation part is not mm)
                    a.plot(q, r[:, k] * rs, ls="", marker="o", ms=2.2, mew=0,  # markers: Agg draws them in C
                           color=AXIS_RGB[k] if r.shape[1] > 1 else col)
                a.axhline(0, color="k", lw=0.5)
                if row == 1:
                    a.set_xlabel(f"{n} ({unit})")
                else:
                    a.tick_params(labelbottom=False)
                if j % ncols == 0:
                    a.set_ylabel(("before" if row == 0 else "after") + f" ({mm})")
    return _svg(fig)


def per_axis(t_s: np.ndarray, after: np.ndarray, x_label: str = "time since first measurement (s)") -> str:
    """The Delta's residuals per axis (x red, y green, z blue) against time."""
    with rc_context(RC):
        fig, ax = _fig(6.4, 2.8)
        a = ax[0, 0]
        for k, c in zip(range(after.shape[1]), "xyz"):
            a.scatter(t_s, after[:, k] * MM, s=10, color=AXIS_RGB[k], label=c, linewidths=0)
        a.axhline(0, color="k", lw=0.5)
        a.set_xlabel(x_label)
        a.set_ylabel("residual after (mm)")
        a.legend()
    return _svg(fig)


def image_field(pixel: np.ndarray, after: np.ndarray, size: tuple[int, int] = (640, 480)) -> str:
    """The scanner's residuals (3-D, mm) drawn at their image points: arrows of the x/y components,
    colour = 3-D norm."""
    with rc_context(RC):
        fig, ax = _fig(6.0, 4.2)
        a = ax[0, 0]
        e = np.linalg.norm(after, axis=1) * MM
        q = a.quiver(pixel[:, 0], pixel[:, 1], after[:, 0] * MM, after[:, 1] * MM, e, cmap="viridis", angles="xy")
        fig.colorbar(q, ax=a, label="|residual| (mm)")
        a.set_xlim(0, size[0])
        a.set_ylim(size[1], 0)
        a.set_xlabel("U (px)")
        a.set_ylabel("V (px)")
    return _svg(fig)


def accuracy_section(art: RunArtefacts) -> str:
    """The verdict, the accuracy map and the residual views (empty if nothing to show)."""
    acc = art.accuracy
    html = ""
    if isinstance(acc, dict):
        st = acc.get("status", "pass")
        cls = {"pass": "pass", "insufficient": "fail", "fail": "fail"}.get(st, "warn")
        html += f'<p>Status <span class="badge {cls}" id="accuracy-status">{escape(st)}</span>'
        if acc.get("reason"):
            html += f" — {escape(acc['reason'])}</p><p><b>Advice:</b> {escape(acc.get('advice', ''))}</p>"
        else:
            html += "</p>"
        m = acc.get("map", {})
        rows = [("predicted 1σ over the map (RMS)", _mm(acc.get("map_rms_1sigma_m"))),
                ("worst 1σ", _mm(acc.get("map_max_1sigma_m"))), ("worst 95 % bound", _mm(acc.get("map_max_bound95_m"))),
                ("uncalibrated 1σ (priors, RMS)", _mm(acc.get("map_uncalibrated_rms_1sigma_m"))),
                ("residuals per identified parameter", f"{acc.get('residuals_per_parameter', 0):.3g}")]
        if isinstance(acc.get("new_measurement"), dict):  # what a new session measures (robocal evaluate)
            rows.insert(1, ("predicted for a new session or posture, measured as here (RMS 3-D)",
                            _mm(acc["new_measurement"].get("rms_3d_m"))))
        info = acc.get("information") or {}
        if info:
            rows.append(("distinct measurements / residual degrees of freedom",
                         f"{info.get('n_distinct')} of {info.get('n_measurements')} / {info.get('dof')}"))
        ho = acc.get("holdout_check") or {}
        if ho:
            rows.append(("held-out RMS / predicted by σ̂ and the design",
                         f"{_mm(ho.get('holdout_rms_m'))} / {_mm(ho.get('predicted_holdout_rms_m'))} "
                         f"(p = {float(ho.get('p_value', 1)):.2g}"
                         + (f"; stated accuracy inflated ×{float(ho['inflation']):.2f})" if not ho.get("consistent", True)
                            else ")")))
        tol = acc.get("tolerance")
        if tol:
            rows.append(("tolerance", f"{_mm(tol['tolerance_m'])}: {tol['status']} ({tol['points_within']} of "
                                      f"{tol['points']} points within)"))
        html += "<table><tbody>" + "".join(f"<tr><td>{escape(k)}</td><td class=\"n\">{escape(v)}</td></tr>"
                                           for k, v in rows) + "</tbody></table>"
        html += f'<p class="note">Map: {escape(str(m.get("description", "")))}. {escape(acc.get("note", ""))}</p>'
        pts = np.asarray(m.get("points_m", []), float).reshape(-1, 3)
        sig = np.asarray(m.get("sigma_m", []), float)
        if pts.size and sig.size == len(pts):
            obs = art.observe or {}
            meas = np.asarray(obs.get("predicted_points_m", []), float).reshape(-1, 3) if obs else None
            html += _fig_html(map_and_coverage(pts, sig, meas), "Accuracy map: predicted 3-D 1σ of the calibrated "
                              "point at each map point (colour, mm), and where the campaign measured (×): "
                              "3-D measurement coverage.", "fig-accuracy-map")
        contrib = acc.get("fixed_parameter_contributions") or []
        if contrib:
            html += "<h3>Fixed parameters that limit the accuracy</h3><table><thead><tr><th>parameter</th>" \
                    "<th>unabsorbed effect (RMS over the map, at its prior 1σ)</th></tr></thead><tbody>" + "".join(
                        f"<tr><td><code>{escape(c['name'])}</code></td><td class=\"n\">{_mm(c['rms_m'])}</td></tr>"
                        for c in contrib) + "</tbody></table>"
        prev = acc.get("previous")
        if prev:
            moved = prev.get("moved", [])
            html += (f"<h3>Compared with {escape(prev['run'])}</h3><p>{prev['compared']} parameters compared; "
                     f"{len(moved)} moved by more than {prev['threshold_sigma']:g}σ"
                     + (": " + escape(", ".join(f"{x['name']} ({x['z']:+.1f}σ)" for x in moved)) if moved else "")
                     + ".</p>")
    before, after = residual_matrix(art.residuals, "before"), residual_matrix(art.residuals, "after")
    used = art.used
    if after.size:
        ru = art.fit.get("residual_unit")
        html += _fig_html(histograms(before[used], after[used], art.fit.get("sigma_m"), ru),
                          "Residual histograms before and after calibration (separate scales), the noise floor "
                          "(residual σ) dashed.", "fig-histograms")
        joints = art.joint_columns()
        if joints:
            from pipeline.report.labels import joints_unit_phrase

            unit = joints_unit_phrase(joints, art.prismatic_joints())
            html += _fig_html(joints_before_after(joints, before, after, art.prismatic_joints(), ru),
                              "Residuals against each joint angle, before "
                              f"(top) and after (bottom) calibration ({'px' if ru == 'px' else 'mm'} vs {unit}); "
                              + ("u/v components red/green." if ru == "px" else "x/y/z components red/green/blue."),
                              "fig-joints-before-after")
        meas = art.measurements or {}
        if art.system == "scorbot-scanner" and "pixel" in meas:
            html += _fig_html(image_field(np.asarray(meas["pixel"], float).reshape(-1, 2), after),
                              "Scanner: residuals after calibration at their image points (arrows: x/y components, "
                              "colour: 3-D norm, mm).", "fig-image-field")
        if after.shape[1] == 3 and "timestamp_ns" in art.residuals:
            from pipeline.report.labels import time_axis

            x, x_label = time_axis(np.asarray(art.residuals["timestamp_ns"], np.int64))
            html += _fig_html(per_axis(x, after, x_label),
                              "Residuals after calibration per axis "
                              "(x red, y green, z blue).", "fig-per-axis")
    return f'<section id="accuracy"><h2>Accuracy</h2>{html}</section>' if html else ""
