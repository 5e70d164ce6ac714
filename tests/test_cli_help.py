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


TREE = """
import json, sys
import typer
from pipeline.cli import app, load_commands
load_commands(sys.argv[1:2] or None)
def walk(cmd, path=()):
    yield " ".join(path)
    for name, sub in getattr(cmd, "commands", {}).items():
        yield from walk(sub, path + (name,))
print(json.dumps(sorted(walk(typer.main.get_command(app)))))
"""


def test_each_command_loads_only_its_modules_and_all_of_its_subcommands():
    """`robocal NAME` imports only the modules COMMAND_MODULES names for NAME (a fresh interpreter each):
    NAME's whole command tree is there as when every module is loaded, but not every other command, and
    device-sim (which runs a simulator in-process) has every simulator."""
    import json
    import subprocess
    import sys

    from pipeline.cli import COMMAND_MODULES

    def tree(*argv: str) -> set[str]:
        p = subprocess.run([sys.executable, "-c", TREE, *argv], capture_output=True, text=True, check=True)
        return set(json.loads(p.stdout))

    full = tree()
    top = {p for p in full if p and " " not in p}
    assert top == set(COMMAND_MODULES), top ^ set(COMMAND_MODULES)  # a new command must be mapped
    for name in sorted(top):
        lazy = tree(name)
        sub = {p for p in full if p == name or p.startswith(name + " ")}
        assert sub <= lazy, (name, sub - lazy)
        assert len(lazy) < len(full) or name == "device-sim", f"{name} loaded every module"
    assert {p for p in full if p.startswith("simulate")} <= tree("device-sim")
