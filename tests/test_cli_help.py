"""Every command and sub-command answers --help (exit 0, a usage line and a description)."""

from __future__ import annotations

import typer
from typer.testing import CliRunner

from pipeline.cli import app, load_commands


def _walk(cmd, path: tuple[str, ...] = ()):
    yield path, cmd
    if hasattr(cmd, "commands"):
        for name, sub in cmd.commands.items():
            yield from _walk(sub, path + (name,))


def test_every_command_has_help():
    load_commands()
    root = typer.main.get_command(app)
    paths = list(_walk(root))
    names = {" ".join(p) for p, _ in paths}
    for expected in ("calibrate", "run", "ingest", "validate", "identify", "observe", "report", "view", "diagnose",
                     "plan", "reprocess", "acquire", "device-sim", "recover", "simulate arc-welder",
                     "simulate scorbot-scanner", "simulate delta-tracker", "import csv", "import ros2"):
        assert expected in names, f"missing command {expected!r}"
    runner = CliRunner()
    for path, cmd in paths:
        res = runner.invoke(app, [*path, "--help"])
        assert res.exit_code == 0, (path, res.output)
        assert "Usage" in res.output, path
        assert (cmd.help or cmd.short_help or "").strip(), f"{' '.join(path) or 'robocal'} has no description"
