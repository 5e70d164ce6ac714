"""`robocal compensate RUN_DIR --targets TARGETS.csv --out PROGRAM.csv`."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.markup import escape

from pipeline.cli import PLAN, app, err


@app.command("compensate", rich_help_panel=PLAN)
def compensate_cmd(
    run_dir: Path = typer.Argument(..., help="Run directory of a calibration (robocal run REC --out RUN_DIR)."),
    targets: Path = typer.Option(..., "--targets", help="Targets CSV: x,y,z (m, work frame) [, qw,qx,qy,qz] "
                                 "[, q_<joint> nominal joints to keep the branch] [, name]."),
    out: Path = typer.Option(..., "--out", help="Program CSV to write: calibrated joints, corrected targets for a "
                             "nominal controller, status and predicted σ per row."),
    payload: Optional[list[str]] = typer.Option(None, "--payload", help="A mass the program carries, KG@LINK or "
                                                "KG@LINK:X,Y,Z (centre of mass in the link frame, m); repeatable. "
                                                "Needs a calibration with physics terms."),
    physics: str = typer.Option("auto", "--physics", help="auto: the calibrated physics terms deflect the robot "
                                "under its gravity (and --payload); none: the rigid calibrated robot."),
    tip: Optional[str] = typer.Option(None, "--tip", help="A URDF tree's tip link the targets are for (default: "
                                      "the recording's first tip)."),
    approach: int = typer.Option(0, "--approach", help="Direction every joint moves in as it reaches its target, "
                                 "for a calibrated backlash: +1 (towards higher values), -1, or 0 (unknown: the "
                                 "middle of the play)."),
) -> None:
    """Inverse kinematics of the calibrated model for a program of Cartesian targets (see docs/guide/compensate.md)."""
    import time

    from pipeline.compensate import program as pg
    from pipeline.errors import RobocalError
    from pipeline.recording.output import check_output
    from pipeline.stages.artefacts import write_json

    if approach not in (-1, 0, 1):
        raise RobocalError(f"--approach {approach}: expected -1, 0 or 1")
    if out.resolve() == targets.resolve():
        raise RobocalError(f"{out}: --out would overwrite the targets file")
    check_output(out, "program")  # never over a file robocal did not create (its own programs are replaced)
    run = pg.load_run(run_dir)
    names = pg.joint_names(run["model"])
    tg = pg.read_targets(targets, names, pg.joint_ranges(run["model"]))
    from pipeline.physics.compliance import parse_payload

    if physics not in ("auto", "none"):
        raise RobocalError(f"--physics {physics!r}: expected auto or none")
    load = parse_payload(payload)
    for w in pg.check_payload(run, load, payload or ()):
        err.print(f"[yellow]warning:[/] {escape(w)}", highlight=False, soft_wrap=True)
    t0 = time.perf_counter()
    c = pg.compensate_run(run, tg, load, physics == "auto", tip, approach)
    sigma = pg.predicted_sigma(run["model"], run["x"], run["free"], run["cov"], c.q)
    elapsed = time.perf_counter() - t0
    pg.write_program(out, c, tg, names, sigma)
    doc = pg.summary(run, c, sigma, targets, out) | {"elapsed_s_note": "see the command's output"}
    write_json(Path(run_dir) / "compensation" / "compensation.json", doc)
    counts = ", ".join(f"{v} {k}" for k, v in doc["status_counts"].items())
    sig = doc["predicted_sigma_rms_m"]
    b95 = doc["predicted_rms_bound95_m"]
    mm = lambda v: f"{v * 1e3:.4f}" if v is not None else "nan"  # noqa: E731
    err.print(f"compensated {c.q.shape[0]} targets in {elapsed:.3f} s: {counts}; predicted accuracy (95 %): tool-point "
              f"RMS ≤ {mm(b95)} mm (1σ RMS {mm(sig)} mm, expected over calibrations); median correction "
              f"{(doc['correction_median_m'] or float('nan')) * 1e3:.3f} mm", highlight=False)
    bad = [r for r in doc["rows"] if r["status"] != "ok"][:5]
    for r in bad:
        err.print(f"  row {r['row']}: {r['status']}", highlight=False)
    print(out)
