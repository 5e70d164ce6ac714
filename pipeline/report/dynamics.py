"""The report of a dynamics identification: report.html (torque measured vs predicted per fitted joint,
held-out residuals against velocity and position, the model choice, condition number, base parameters
with σ, the physically consistent inertials) and run.rrd (the torque time series in rerun)."""

from __future__ import annotations

from html import escape
from pathlib import Path

import numpy as np

from pipeline.report.markup import figure, section, table
from pipeline.report.plots import RC, _fig, _svg, singular_values

CSS = ("body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}table{border-collapse:collapse}"
       "td,th{border:1px solid #ccc;padding:2px 6px;font-size:12px}td.n{text-align:right}figure{margin:1em 0}")


def _joints(tab: dict) -> list[str]:
    return [k[len("measured_"):] for k in tab if k.startswith("measured_")]


def torque_plot(tab: dict) -> str:
    """Measured, fitted and held-out predicted torque per fitted joint against time."""
    from matplotlib import rc_context

    js = _joints(tab)
    with rc_context(RC):
        fig, ax = _fig(10.0, 2.0 * len(js), nrows=len(js), sharex=True)
        for a, j in zip(ax[:, 0], js):
            a.plot(tab["t_s"], tab[f"measured_{j}"], lw=0.5, color="#7f7f7f", label="measured")
            a.plot(tab["t_s"], tab[f"fitted_{j}"], lw=0.8, color="#1f77b4", label="fitted")
            if f"holdout_{j}" in tab:
                a.plot(tab["t_s"], tab[f"holdout_{j}"], lw=0.8, color="#d62728", label="held out")
            a.set_ylabel(f"{j} N·m")
        ax[0, 0].legend(loc="upper right", ncol=3)
        ax[-1, 0].set_xlabel("time s")
    return _svg(fig)


def residual_plot(tab: dict, key: str, label: str) -> str:
    """Held-out residual (predicted − measured) of each fitted joint against its velocity or position."""
    from matplotlib import rc_context

    js = _joints(tab)
    with rc_context(RC):
        fig, ax = _fig(10.0, 2.2, ncols=len(js))
        for a, j in zip(ax[0, :], js):
            r = tab.get(f"holdout_{j}", tab[f"fitted_{j}"]) - tab[f"measured_{j}"]
            a.plot(tab[f"{key}_{j}"], r, ".", ms=1, alpha=0.3, color="#1f77b4")
            a.set_title(j)
            a.set_xlabel(label)
        ax[0, 0].set_ylabel("held-out residual N·m")
    return _svg(fig)


def render(fit: dict, tab: dict, observe: dict | None) -> str:
    js = fit["fit_joints"]
    f = lambda v: "—" if v is None else f"{v:.4f}"  # noqa: E731
    rows = [[escape(j), f(fit["nominal_rms_joint_Nm"][j]), f(fit["rms_after_joint_Nm"][j]),
             f(fit["holdout_rms_joint_Nm"][j]),
             f((fit.get("consistent", {}).get("holdout_rms_joint_Nm") or {}).get(j))] for j in js]
    pooled = lambda d: float(np.sqrt(np.mean(np.square(list(d.values())))))  # noqa: E731
    cons = fit.get("consistent", {})
    rows.append(["pooled", f(fit["nominal_rms_Nm"]), f(fit["rms_after_Nm"]), f(fit["holdout_rms_Nm"]),
                 f(pooled(cons["holdout_rms_joint_Nm"]) if cons.get("holdout_rms_joint_Nm") else None)])
    parts = [section("figures", "Torque RMS per fitted joint (N·m; N for a prismatic joint)",
                     table(["joint", "URDF as drawn", "fit", "held-out (chosen model)", "held-out (physically consistent)"],
                           rows, {1, 2, 3, 4}) +
                     f"<p>Held-out: {escape(fit['holdout_kind'])}. Model choice: {escape(fit['model_choice_label'])} "
                     f"(the held-out arbiter; every candidate below).</p>")]
    cand = [[escape(c["choice"]), f(c.get("holdout_rms"))] for c in fit["model_choice"]["candidates"]]
    parts.append(section("choice", "Model choice", table(["candidate", "held-out RMS N·m"], cand, {1})))
    parts.append(section("torques", "Torque measured and predicted", figure(torque_plot(tab), "per fitted joint",
                                                                            "fig-torque")))
    parts.append(section("residuals", "Residuals against velocity and position",
                         figure(residual_plot(tab, "v", "velocity rad/s"), "held-out residual vs velocity", "fig-rv") +
                         figure(residual_plot(tab, "q", "position rad"), "held-out residual vs position", "fig-rq")))
    sv = np.asarray(fit["singular_values"], float)
    parts.append(section("observe", f"Base regressor: {fit['n_identifiable']} base parameters, condition number "
                         f"{fit['condition_number']:.1f}", figure(singular_values(sv), "singular values", "fig-sv")))
    base = [[escape(n), f"{b:.6g}", f"{s:.3g}"] for n, b, s in zip(fit["base_names"], fit["beta"], fit["beta_std"])]
    parts.append(section("parameters", "Base parameters (chosen model) and their σ", table(["combination", "value", "σ"],
                                                                                            base, {1, 2})))
    if cons:
        ok = cons["bodies_consistent"]
        parts.append(section("consistent", "Physically consistent inertials (model.urdf)",
                             f"<p>{sum(ok)} of {len(ok)} bodies pass the pseudo-inertia check (positive mass, "
                             f"triangle inequalities); fit RMS {cons['rms_after_Nm']:.4f} N·m.</p>"))
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>robocal dynamics</title><style>{CSS}</style>"
            f"</head><body><h1>robocal — dynamics identification</h1>{''.join(parts)}</body></html>")


def write_rrd(tab: dict, path: Path) -> list[str]:
    """Torque time series (measured, fitted, held out) per fitted joint on the timeline `time`."""
    import rerun as rr

    rec = rr.RecordingStream("robocal", recording_id="robocal-dynamics", send_properties=False)
    rec.save(str(path), default_blueprint=None)
    idx = rr.TimeColumn("time", duration=np.asarray(tab["t_s"], float))
    paths = []
    for j in _joints(tab):
        for kind in ("measured", "fitted", "holdout"):
            if f"{kind}_{j}" in tab:
                p = f"dynamics/torque/{j}/{kind}"
                rec.send_columns(p, indexes=[idx], columns=rr.Scalars.columns(scalars=np.asarray(tab[f"{kind}_{j}"])))
                paths.append(p)
    rec.flush()
    return paths


def write_report(run_dir: Path, params: dict, html_name: str, rrd_name: str) -> dict:
    from pipeline.stages.artefacts import read_json, read_table

    fit = read_json(run_dir / "identify" / "fit.json")
    tab = read_table(run_dir / "identify" / "torques.parquet")
    obs = run_dir / "observe" / "observe.json"
    out: dict = {"files": {}, "family": "dynamics", "holdout_rms_Nm": fit["holdout_rms_Nm"]}
    if params.get("html", True):
        (run_dir / html_name).write_text(render(fit, tab, read_json(obs) if obs.is_file() else None), encoding="utf-8")
        out["files"]["html"] = html_name
    if params.get("rrd", True):
        out["rrd_entities"] = write_rrd(tab, run_dir / rrd_name)
        out["files"]["rrd"] = rrd_name
    out["outputs"] = sorted(out["files"].values())
    return out
