"""`robocal reprocess`: an archive of recordings through the pipeline on Dask, results streamed to a
Parquet dataset, compared with expected figures."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Literal, Optional

import typer
from rich.console import Console
from rich.progress import (BarColumn, MofNCompleteColumn, Progress, ProgressColumn, TextColumn, TimeElapsedColumn,
                           TimeRemainingColumn)
from rich.table import Table
from rich.text import Text

from pipeline.cli import FLEET, app, err

MAX_TABLE_ROWS = 50


class RateColumn(ProgressColumn):
    """Recordings per second (rich's moving estimate)."""

    def render(self, task) -> Text:
        return Text("—/s" if not task.speed else f"{task.speed:.2f} rec/s", style="progress.data.speed")


@app.command("reprocess", rich_help_panel=FLEET)
def reprocess_cmd(
    archive: Path = typer.Argument(..., help="Archive folder: recordings found recursively (see --pattern), each "
                                   "optionally with <stem>.expected.json beside it."),
    out: Path = typer.Option(..., "--out", help="Output folder: results/ (Parquet dataset, one row per recording, "
                             "written as tasks complete), runs/<path>/ (one run folder per recording), "
                             "summary.json/.csv."),
    pattern: list[str] = typer.Option([], "--pattern", help="Glob over paths relative to ARCHIVE (repeatable; "
                                      "default **/*.mcap). Symlinks are followed only inside the archive."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Existing Dask scheduler, tcp://HOST:PORT "
                                            "(its workers must see ARCHIVE and --out at the same paths). Default: "
                                            "a local cluster of --workers processes."),
    workers: Optional[int] = typer.Option(None, "--workers", min=1, help="Local workers (default: CPU count)."),
    engine: Literal["dask", "processes", "serial"] = typer.Option("dask", "--engine", help="dask, processes (a local process pool) or "
                               "serial (in this process)."),
    core: bool = typer.Option(False, "--core", help="Only ingest, validate, identify, observe (no diagnose/report)."),
    stages_opt: str = typer.Option("", "--stages", help="Comma-separated stages to run instead (e.g. "
                                   "ingest,validate,identify: enough for the fleet history)."),
    robot_id: Optional[str] = typer.Option(None, "--robot-id", help="Robot identity for every recording (overrides "
                                           "the campaign metadata's robot_id)."),
    resume: bool = typer.Option(True, "--resume/--no-resume", help="Skip recordings already in OUT/results with the "
                                "same input hash, robocal version and options."),
    allowed_failures: Optional[int] = typer.Option(None, "--allowed-failures", min=0, help="Local cluster: times a "
                                                   "task may lose its worker before it is recorded as lost "
                                                   "(Dask's distributed.scheduler.allowed-failures, default 3)."),
    flush_s: float = typer.Option(2.0, "--flush-s", min=0.01, help="A finished row is on disk (a new Parquet part) "
                                  "at most this many seconds later: what an interrupted run keeps."),
) -> None:
    """Reprocess every recording of ARCHIVE; exit 1 on any regression or failed recording."""
    from pipeline.errors import RobocalError
    from pipeline.fleet import fork_server
    from pipeline.stages.registry import BY_NAME, CORE_STAGES

    if not archive.is_dir():
        raise RobocalError(f"{archive}: not a folder")
    if scheduler and engine != "dask":
        raise RobocalError("--scheduler needs --engine dask")
    stages = [s.strip() for s in stages_opt.split(",") if s.strip()] or (CORE_STAGES if core else None)
    unknown = [s for s in stages or [] if s not in BY_NAME]
    if unknown:
        raise RobocalError(f"--stages: unknown stage(s) {', '.join(unknown)} (stages: {', '.join(BY_NAME)})")
    # a local cluster: its workers' fork server imports while this process imports the engine and plans
    early_server = engine == "dask" and not scheduler and fork_server.start_if_fresh(out, stages)
    from pipeline.fleet.engine import ENGINES, reprocess_archive  # (an error before the run: stopped at exit)
    if engine not in ENGINES:
        raise RobocalError(f"--engine {engine}: not one of {', '.join(ENGINES)}")
    from pipeline.stages.reprocess import write_summary
    counts = {"ok": 0, "failed": 0, "regressed": 0, "skipped": 0}
    progress = Progress(TextColumn("[bold]reprocess"), BarColumn(), MofNCompleteColumn(),
                        TextColumn("[green]{task.fields[ok]} ok[/] [red]{task.fields[failed]} failed[/] "
                                   "[yellow]{task.fields[regressed]} regressed[/] {task.fields[skipped]} done before"),
                        RateColumn(), TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
                        console=err if err.is_terminal else Console(stderr=True, width=160), transient=False,
                        disable=not err.is_terminal)  # a log or CI job gets lines instead (pipeline.progress)
    from pipeline.progress import Ticker

    lines = None if err.is_terminal else Ticker("reprocess", unit="recordings", tty=False)
    bar = None

    def on_plan(n_todo: int, n_kept: int) -> None:
        nonlocal bar
        counts["skipped"] = n_kept
        bar = progress.add_task("reprocess", total=n_todo, **counts)
        if lines is not None:
            lines.total = n_todo
            lines.stream.write(f"reprocess: {n_todo} recording(s) to process, {n_kept} done before\n")
            lines.wrote = True  # and a last line with the counts at the end

    def on_row(row: dict) -> None:
        key = "failed" if row["status"] in ("fail", "error", "crash", "lost") else "regressed" \
            if row["regressions"] else "ok"
        counts[key] += 1
        progress.update(bar, advance=1, **counts)
        if lines is not None:
            lines(f"{counts['ok']} ok, {counts['failed']} failed, {counts['regressed']} regressed")

    def on_start(client) -> None:
        n = len(client.scheduler_info().get("workers", {}))
        progress.console.print(f"Dask scheduler {client.scheduler.address}: {n} worker(s)", highlight=False)

    try:
        with progress:
            res = reprocess_archive(archive, out, patterns=tuple(pattern) or ("**/*.mcap",), stages=stages,
                                    robot_id=robot_id, engine=engine, workers=workers, scheduler=scheduler,
                                    allowed_failures=allowed_failures, resume=resume, flush_s=flush_s,
                                    on_plan=on_plan, on_row=on_row, on_start=on_start)
    finally:
        if early_server:
            fork_server.stop()  # the cluster is closed: nothing is forked from it any more
    if lines is not None:
        lines.done(f"{counts['ok']} ok, {counts['failed']} failed, {counts['regressed']} regressed")
    rows = res.all_rows
    for s in res.skipped_paths:
        err.print(f"[yellow]skipped[/] {s}", highlight=False)
    if not rows:
        raise RobocalError(f"{archive}: no recordings (patterns {', '.join(pattern) or '**/*.mcap'})")
    write_summary(rows, out)
    _print_table(archive, rows)
    bad = [r for r in rows if not r["ok"]]
    err.print(f"results: {out / 'results'} (Parquet dataset), summary: {out / 'summary.csv'}")
    if bad:
        err.print(f"[bold red]{len(bad)} of {len(rows)} recording(s) regressed or failed[/]")
        raise typer.Exit(1)
    err.print(f"[green]all {len(rows)} recording(s) as expected[/]")


def _print_table(archive: Path, rows: list[dict]) -> None:
    def unit_of(r: dict) -> str | None:
        """px for a camera's run (fit.json's residual_unit), else None (metres, shown in mm)."""
        from pipeline.stages.artefacts import read_json

        fit = Path(r["run_dir"]) / "identify" / "fit.json" if r.get("run_dir") else None
        try:
            return read_json(fit).get("residual_unit") if fit is not None and fit.is_file() else None
        except Exception:  # noqa: BLE001 — a damaged fit.json: the row's own status says so
            return None

    def mm(v, unit=None):
        if v is None:
            return "—"
        return f"{v:.4f} px" if unit == "px" else f"{v * 1e3:.4f}"
    shown = rows if len(rows) <= MAX_TABLE_ROWS else [r for r in rows if not r["ok"]][:MAX_TABLE_ROWS]
    if not shown:
        return
    title = f"robocal reprocess — {archive}" + ("" if shown is rows else
                                               f" ({len(shown)} of {len(rows)} shown: the failed or regressed)")
    t = Table(title=title)
    for c in ("recording", "robot", "system", "meas.", "RMS before mm", "RMS after mm", "held-out mm",
              "identifiable", "status", "vs expected"):
        t.add_column(c)
    for r in shown:
        u = unit_of(r)
        verdict = ("[green]ok[/]" if not r["regressions"] else "[red]" + "; ".join(r["regressions"]) + "[/]") \
            if r["expected"] else "[yellow]no expected figures[/]"
        status = str(r.get("status")) + (f": {r['error']}" if r.get("error") else "")
        t.add_row(r["recording"], str(r.get("robot_id") or "—"), str(r.get("system") or "—"),
                  str(r.get("n_measurements") or "—"), mm(r.get("rms_before_m"), u), mm(r.get("rms_after_m"), u),
                  mm(r.get("holdout_rms_m"), u), str(r.get("n_identifiable") or "—"), status, verdict)
    Console(width=None if sys.stdout.isatty() else 160).print(t)
