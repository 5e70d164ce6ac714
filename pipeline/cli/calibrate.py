"""`robocal calibrate`."""

from __future__ import annotations

from pathlib import Path
from typing import Literal, Optional

import typer
from rich.markup import escape
from rich.table import Table

from pipeline.cli import CALIBRATE, app, console, err
from pipeline.cli.run import (MODEL_CHOICE_HELP, PAYLOAD, PHYSICS, PREVIOUS, PRIOR, STRICT, TARGETS, TOLERANCE, accuracy_params,
                              strict_exit)


@app.command("calibrate", rich_help_panel=CALIBRATE)
def calibrate_cmd(
    recordings: list[Path] = typer.Argument(..., help="Recording(s) (MCAP) of a calibration campaign; several "
                                                      "recordings of one robot are calibrated together (sessions)."),
    out: Path = typer.Option(..., "--out", help="Output folder for results.json and model.json."),
    loss: Literal["linear", "huber", "soft_l1"] = typer.Option("linear", "--loss", help="Robust loss."),
    folds: int = typer.Option(5, "--folds", min=2, help="Folds of the held-out cross-validation."),
    rank_tol: float = typer.Option(1e-3, "--rank-tol", min=0.0,
                                   help="Smallest remaining norm of a kept unit-norm Jacobian column (rank test)."),
    solver: Literal["lm", "ga"] = typer.Option("lm", "--solver", help="lm (least squares) or ga (seed 001's genetic algorithm)."),
    joint_offsets: bool = typer.Option(False, "--joint-offsets", help="Also identify the arm's joint offsets (scanner)."),
    variant: str = typer.Option(None, "--model-variant",
                                help="Model variant of the system (delta-tracker: simplified, extended)."),
    prior: Optional[list[str]] = PRIOR, tolerance: Optional[str] = TOLERANCE, previous: Optional[Path] = PREVIOUS,
    targets: Optional[Path] = TARGETS, strict: bool = STRICT,
    registration: Literal["shared", "per-recording"] = typer.Option("shared", "--registration", help="Several recordings: shared (one instrument "
                                                                      "frame) or per-recording."),
    model_choice: Literal["auto", "groups", "shrinkage"] = typer.Option("auto", "--model-choice", help=MODEL_CHOICE_HELP),
    physics: Optional[str] = PHYSICS, payload: Optional[list[str]] = PAYLOAD,
) -> None:
    """Identify the robot model from a recording: full nonlinear least squares from the nominal model."""
    from pipeline.calibrate import calibrate, summary_rows
    from pipeline.identify.least_squares import FitOptions
    from pipeline.importers.merge import merged_input

    recording = merged_input(recordings, out, registration, run_folder=False)
    if physics is not None or payload:
        from pipeline.physics.payload import check_physics_input

        for w in check_physics_input(recording, physics, payload):  # one line naming the element, before the fit
            err.print(f"[yellow]warning:[/] {escape(w)}", highlight=False, soft_wrap=True)

    with err.status(f"calibrating {recording}…"):
        doc = calibrate(recording, out, FitOptions(loss=loss, rank_tol=rank_tol), k_folds=folds, solver=solver,
                        joint_offsets=joint_offsets, variant=variant, physics=physics, payload=payload,
                        model_choice=model_choice,
                        accuracy=accuracy_params(prior, tolerance, previous, targets))
    for w in doc["warnings"]:
        err.print(f"[yellow]warning:[/] {escape(w)}", highlight=False)
    t = Table(title=f"robocal calibrate — {recording.name}")
    t.add_column("figure")
    t.add_column("value", justify="right")
    for k, v in summary_rows(doc):
        t.add_row(k, v)
    console().print(t)
    if doc.get("physics"):
        from pipeline.physics.summary import lines

        for line in lines(doc["physics"]):
            err.print(line, highlight=False)
    if doc.get("status_reason"):
        err.print(f"[red]{doc['status']}:[/] {doc['status_reason']}", highlight=False)
        err.print(f"advice: {doc['status_advice']}", highlight=False)
    for m in doc["accuracy"].get("previous", {}).get("moved", []):
        err.print(f"moved since {previous}: {m['name']} by {m['change']:.3g} {m['unit']} ({m['z']:+.1f}σ)", highlight=False)
    print(f"results: {out / 'results.json'}\nmodel:   {out / 'model.json'}")
    strict_exit(doc["status"], strict)
