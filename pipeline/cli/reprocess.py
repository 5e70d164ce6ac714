"""`robocal reprocess`: the pipeline over a folder of recordings, compared with expected figures."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.table import Table

from pipeline.cli import app, err


@app.command("reprocess")
def reprocess_cmd(
    folder: Path = typer.Argument(..., help="Folder of recordings (*.mcap), each optionally with <stem>.expected.json."),
    out: Path = typer.Option(..., "--out", help="Output folder: one run folder per recording, summary.json/.csv."),
    workers: Optional[int] = typer.Option(None, "--workers", min=1, help="Parallel processes (default: CPU count)."),
    core: bool = typer.Option(False, "--core", help="Only ingest, validate, identify, observe (no diagnose/report)."),
) -> None:
    """Run every recording of FOLDER through the pipeline in parallel; exit 1 on any regression."""
    from pipeline.errors import RobocalError
    from pipeline.stages.reprocess import reprocess, write_summary

    if not folder.is_dir():
        raise RobocalError(f"{folder}: not a folder")
    stages = ["ingest", "validate", "identify", "observe"] if core else None
    with err.status(f"reprocessing {folder}…"):
        rows = reprocess(folder, out, workers, stages)
    if not rows:
        raise RobocalError(f"{folder}: no recordings (*.mcap)")
    write_summary(rows, out)
    mm = lambda v: "—" if v is None else f"{v * 1e3:.4f}"  # noqa: E731
    t = Table(title=f"robocal reprocess — {folder}")
    for c in ("recording", "system", "meas.", "RMS before mm", "RMS after mm", "held-out mm", "identifiable",
              "status", "vs expected"):
        t.add_column(c)
    for r in rows:
        verdict = ("[green]ok[/]" if not r["regressions"] else "[red]" + "; ".join(r["regressions"]) + "[/]") \
            if r["expected"] else "[yellow]no expected figures[/]"
        t.add_row(r["recording"], str(r.get("system") or "—"), str(r.get("n_measurements") or "—"),
                  mm(r.get("rms_before_m")), mm(r.get("rms_after_m")), mm(r.get("holdout_rms_m")),
                  str(r.get("n_identifiable") or "—"), str(r.get("status")), verdict)
    import sys

    Console(width=None if sys.stdout.isatty() else 160).print(t)
    bad = [r for r in rows if not r["ok"]]
    err.print(f"summary: {out / 'summary.csv'}")
    if bad:
        err.print(f"[bold red]{len(bad)} of {len(rows)} recording(s) regressed or failed[/]")
        raise typer.Exit(1)
    err.print(f"[green]all {len(rows)} recording(s) as expected[/]")
