"""`robocal diagnose`: find the physics the geometric model left out."""

from __future__ import annotations

from pathlib import Path

import typer

from pipeline.cli import CALIBRATE, app, console, err


@app.command("diagnose", rich_help_panel=CALIBRATE)
def diagnose_cmd(
    recording: Path = typer.Argument(..., help="Recording (MCAP) of a calibration campaign."),
    out: Path = typer.Option(..., "--out", help="Output folder for diagnosis.json."),
    alpha: float = typer.Option(0.01, "--alpha", min=1e-6, max=0.2, help="Family-wise error rate (Holm)."),
    folds: int = typer.Option(5, "--folds", min=2, help="Folds of the grouped cross-validation."),
    n_boot: int = typer.Option(40, "--bootstrap", min=0, help="Bootstrap resamples for selection stability."),
    repeatability: float = typer.Option(None, "--repeatability", min=0.0,
                                        help="The robot's declared repeatability, 3σ (m; datasheet, ISO 9283): the "
                                             "noise floor the fit must come back to (default: the recording's "
                                             "campaign metadata robot_repeatability_3sigma_m, else no floor check)."),
) -> None:
    """Locate residual structure, name the effect from the library, model it, show the held-out fit improve."""
    from rich.table import Table

    from pipeline.diagnose import Settings
    from pipeline.diagnose.stage import SUPPORTED, diagnose_recording
    from pipeline.errors import RobocalError
    from pipeline.report.labels import residual_text
    from pipeline.recording.reader import read_recording
    from pipeline.stages.artefacts import write_json
    from pipeline.systems.registry import detect

    from pipeline.dynamics.stage import diagnose_recording as diagnose_dynamics
    from pipeline.dynamics.stage import is_dynamics_recording

    settings = Settings(alpha=alpha, folds=folds, n_boot=n_boot, repeatability_3sigma_m=repeatability)
    with err.status(f"diagnosing {recording}…"):
        rec = read_recording(recording)
        if is_dynamics_recording(rec):  # efforts: identify the dynamics, then its library
            doc = diagnose_dynamics(rec, settings)
        else:
            system = detect(rec)
            if system.SYSTEM not in SUPPORTED:
                raise RobocalError(f"{recording}: diagnosis supports {', '.join(SUPPORTED)}; this is {system.SYSTEM}")
            doc = diagnose_recording(rec, settings)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "diagnosis.json", doc)
    mm = lambda v: residual_text(v, doc.get("residual_unit"))  # noqa: E731 — mm, or px for a camera
    t = Table(title=f"robocal diagnose — {recording.name}")
    t.add_column("effect")
    t.add_column("location")
    t.add_column("parameters (value ± 1σ [95 % CI])")
    t.add_column("p (Holm)", justify="right")
    t.add_column("CV RMS without → with", justify="right")
    t.add_column("boot", justify="right")
    for f in doc["findings"]:
        ev = f["evidence"]
        pars = ", ".join(f"{p['name']}={p['value']:.4g}±{p['std']:.2g}"
                         + (f" [{p['ci95'][0]:.4g}, {p['ci95'][1]:.4g}]" if p.get("ci95") else "") + f" {p['unit']}"
                         for p in f["parameters"])
        alike = ", ".join(f"{a['effect']}@{a['location']}"
                          for a in f.get("look_alikes", []) + f.get("untested_look_alikes", []))
        t.add_row(f["effect"] + ("" if f["confidence"] == "high" else f" ({f['confidence']} confidence)")
                  + (f" (or {alike}: the campaign can hardly tell)" if alike else "")
                  + (f" (runner-up {ru['effect']}@{ru['location']}, Δχ² {ru['delta_chi2']:.3g})"
                     if (ru := f.get("runner_up")) and not alike else ""), f["location"], pars,
                  f"{ev['p_value']:.2g}", f"{mm(ev['cv_rms_before_m'])} → {mm(ev['cv_rms_after_m'])}",
                  f"{ev['bootstrap_frequency']:.2f}")
    con = console()
    model_word = "identified dynamics model" if doc.get("family") == "dynamics" else "geometric model"
    con.print(t if doc["findings"] else f"no effect found beyond the {model_word}")
    dropped = (doc.get("clustered_inference") or {}).get("dropped_by_check") or []
    if dropped:
        con.print("accepted by the F tests but not by the pose sign-flip check (not reported as findings): "
                  + ", ".join(f"{d['effect']}@{d['location']}" for d in dropped), highlight=False)
    if doc["unexplained"]:
        for w in doc["unexplained_where"]:
            reg = w["region"]
            reg = f"[{reg[0]:.3g}, {reg[1]:.3g}]" if isinstance(reg, list) else reg
            con.print(f"[yellow]unexplained structure[/] in {w['variable']} around {reg} (p={w['p_value']:.2g})")
    else:
        con.print("no unexplained structure left in the residuals")
    for o in doc.get("outlier_records", []):
        con.print(f"[yellow]outlier record[/] {o['record']} (face {o['face']}): {o['reason']}", highlight=False)
    for f in doc.get("rejected_findings", []):
        con.print(f"not reported as found: {f['effect']}@{f['location']} — {f['note']}", highlight=False)
    if doc.get("status"):
        fl = doc.get("noise_floor")
        con.print(f"status: [bold]{doc['status'].replace('_', ' ')}[/] — {doc['status_reason']}"
                  + (f" (residual RMS {fl['rms_over_floor']:.2f}× the declared floor {mm(fl['sigma_floor_m'])})"
                     if fl else ""), highlight=False)
    if doc.get("unseen"):  # every status: what the campaign could not have seen, and what would show it
        from pipeline.diagnose.document.unseen import summary_lines

        con.print(f"looked for, and the size each could have had unseen here (found with {doc['unseen'][0]['power']:.0%} "
                  "probability at that size):", highlight=False)
        for line in summary_lines(doc["unseen"]):
            con.print(f"  {line}", highlight=False, soft_wrap=True)
    shown = [n for n in doc["not_identifiable"] if "no effect" not in n["reason"]]
    if shown:
        con.print(f"{len(shown)} effect(s) this campaign cannot separate from the "
                  f"{'base parameters' if doc.get('family') == 'dynamics' else 'geometry'}, e.g.:")
        for n in shown[:4]:
            con.print(f"  {n['effect']}@{n['location']}: {n['reason']} — {n['advice']}", highlight=False)
    con.print(f"held-out RMS {mm(doc['holdout_rms_before_m'])} → {mm(doc['holdout_rms_after_m'])} "
              f"({doc['cross_validation']['folds']}-fold, {doc['cross_validation']['groups']})")
    print(f"diagnosis: {out / 'diagnosis.json'}")
