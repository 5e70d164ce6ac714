"""`robocal fleet SUMMARY --out fleet.html`: each robot's calibrations over time, from a reprocess
results dataset; `robocal simulate fleet`: a simulated monthly fleet archive."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from pipeline.cli import FLEET, app, err, force_option, simulate_app


@app.command("fleet", rich_help_panel=FLEET)
def fleet_cmd(
    summary: Path = typer.Argument(..., help="Reprocess results: the --out folder of `robocal reprocess`, its "
                                   "results/ dataset, or one Parquet file."),
    out: Path = typer.Option(..., "--out", help="Page to write (self-contained HTML); fleet.json beside it ({generator, robots: {id: flags}})."),
    tolerance: Optional[str] = typer.Option(None, "--tolerance", "--tolerance-m", help="Stated accuracy tolerance: "
                                            "held-out RMS above it is flagged; SI metres (2.5e-4) or with a unit "
                                            "(0.25mm), as `run --tolerance`."),
    alpha: float = typer.Option(0.01, "--alpha", min=1e-9, max=0.5, help="Family false-flag rate per robot "
                                "(steps and trends each)."),
) -> None:
    """Per robot: parameters and accuracy over time with σ bands, steps, trends, tolerance, failures."""
    from pipeline.errors import RobocalError
    from pipeline.fleet.dataset import read_results
    from pipeline.fleet.history import fleet_history
    from pipeline.fleet.html import counts, render
    from pipeline.recording.output import check_output
    from pipeline.stages.artefacts import write_json

    tolerance_m = None
    if tolerance is not None:
        from pipeline.accuracy.prior import parse_quantity

        tolerance_m = parse_quantity(tolerance, "--tolerance")
        if not tolerance_m > 0:
            raise RobocalError(f"--tolerance {tolerance!r}: must be positive")
    if out.suffix.lower() == ".json":
        raise RobocalError(f"{out}: the page is HTML (fleet.json is written beside it); give e.g. fleet.html")
    if out.exists() and out.is_dir():
        raise RobocalError(f"{out}: is a folder (give the page's file name, e.g. fleet.html)")
    check_output(out, "fleet page")  # before any work: never over a file robocal did not create
    check_output(out.with_suffix(".json"), "fleet flags")
    rows = read_results(summary).to_pylist()
    if not rows:
        raise RobocalError(f"{summary}: the results dataset has no rows")
    hs = fleet_history(rows, tolerance_m, alpha)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(render(hs, str(summary), tolerance_m, alpha), encoding="utf-8")
    write_json(out.with_suffix(".json"), counts(hs))
    for h in hs:
        flags = [f"step {s['param']} on {_day(s['t_ns'])} (|z| {abs(s['z']):.1f})" for s in h.steps]
        flags += [f"trend {t['param']} (|z| {abs(t['z']):.1f})" for t in h.trends]
        flags += [f"{len(h.tolerance)} above tolerance"] if h.tolerance else []
        flags += [f"identified set changed on {', '.join(_day(c['t_ns']) for c in h.free_set_changes)}"] \
            if h.free_set_changes else []
        flags += [f"{len(h.failed)} failed"] if h.failed else []
        flags += [f"{len(h.insufficient)} insufficient"] if h.insufficient else []
        err.print(f"{h.robot_id}: {len(h.usable)}/{len(h.rows)} calibrations; " + ("; ".join(flags) or "no flags"),
                  highlight=False)
    err.print(f"wrote {out}")


def _day(t_ns: int) -> str:
    from pipeline.fleet.html import day

    return day(t_ns)


@simulate_app.command("fleet")
def simulate_fleet_cmd(
    out: Path = typer.Option(..., "--out", help="Archive folder to write: ROBOT/YYYY-MM/campaign.mcap."),
    robots: int = typer.Option(5, "--robots", min=1),
    months: int = typer.Option(12, "--months", min=1),
    contacts: int = typer.Option(40, "--contacts", min=10),
    seed: int = typer.Option(0, "--seed"),
    step: list[str] = typer.Option([], "--step", help="ROBOT:MONTH:PARAM=VALUE (SI; robot 1-based), e.g. "
                                   "2:7:J3.theta_offset=5e-3."),
    drift: list[str] = typer.Option([], "--drift", help="ROBOT:PARAM=VALUE_PER_MONTH (SI), e.g. 4:J2.a=8e-5."),
    workers: int = typer.Option(1, "--workers", min=1, help="Processes."),
    force: bool = force_option("campaign recording or truth file"),
) -> None:
    """A fleet of arc-welding robots calibrated monthly (truth to ARCHIVE/fleet.truth.json)."""
    from pipeline.errors import MAX_CONTACTS, MAX_COUNT, at_most

    for option, value in (("--robots", robots), ("--months", months), ("--contacts", contacts),):
        at_most(option, value, MAX_CONTACTS if option == "--contacts" else MAX_COUNT)
    from pipeline.errors import RobocalError
    from pipeline.fleet.simulate import Change, FleetSpec, simulate_fleet

    changes = []
    try:
        for s in step:
            r, m, rest = s.split(":", 2)
            p, v = rest.split("=")
            changes.append(Change(int(r) - 1, p, float(v), "step", int(m)))
        for s in drift:
            r, rest = s.split(":", 1)
            p, v = rest.split("=")
            changes.append(Change(int(r) - 1, p, float(v), "drift"))
    except ValueError:
        raise RobocalError(f"--step/--drift {s!r}: expected ROBOT:MONTH:PARAM=VALUE / ROBOT:PARAM=VALUE") from None
    if any(not 0 <= c.robot < robots for c in changes):
        raise RobocalError(f"--step/--drift: robot numbers run from 1 to {robots}")
    try:
        simulate_fleet(out, FleetSpec(robots=robots, months=months, contacts=contacts, seed=seed,
                                      changes=tuple(changes)), workers=workers, force=force)
    except ValueError as e:
        raise RobocalError(str(e)) from None
    err.print(f"wrote {robots * months} recordings under {out}")
