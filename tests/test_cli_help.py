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


def _panels(text: str) -> dict[str, list[str]]:
    """Help panel title → the first word of each of its rows (a rich `--help` page)."""
    import re

    panels: dict[str, list[str]] = {}
    title = None
    for line in text.splitlines():
        m = re.match(r"\s*╭─ (.+?) ─", line)
        if m:
            title = m.group(1)
            panels[title] = []
        elif title and (m := re.match(r"\s*│\s{1,4}(\*\s+)?(\S+)", line)):  # a row, not its wrapped text
            panels[title].append(m.group(2))
    return panels


def test_commands_are_grouped_by_task_in_order():
    """`robocal --help` lists the commands under Import, Calibrate, Plan & compensate, Simulate & acquire,
    Fleet, View — in that order, every command in one of them."""
    from pipeline.cli import PANELS

    load_commands()
    res = CliRunner().invoke(app, ["--help"], terminal_width=200)
    assert res.exit_code == 0, res.output
    panels = _panels(res.output)
    assert [p for p in panels if p != "Options"] == list(PANELS)
    assert sorted(panels["Import"]) == ["export", "import"]  # in the order the commands were loaded
    assert {"run", "calibrate", "diagnose", "evaluate", "report", "ingest", "validate", "identify", "observe"} == set(
        panels["Calibrate"])
    assert set(panels["Plan & compensate"]) == {"plan", "compensate"}
    assert set(panels["Simulate & acquire"]) == {"simulate", "device-sim", "acquire", "recover"}
    assert set(panels["Fleet"]) == {"reprocess", "fleet"}
    assert panels["View"] == ["view"]
    root = typer.main.get_command(app)
    assert sum(len(v) for k, v in panels.items() if k != "Options") == len(root.commands)


def test_flags_are_shown_without_a_value_and_runs_import_options_have_their_panel():
    load_commands()
    runner = CliRunner()
    root = typer.main.get_command(app)
    for path, _ in _walk(root):
        res = runner.invoke(app, [*path, "--help"], terminal_width=200)
        assert "<bool>" not in res.output, (path, res.output)
    panels = _panels(runner.invoke(app, ["run", "--help"], terminal_width=200).output)
    bag = panels["Import (when REC is a ROS 2 bag or needs --urdf)"]
    assert bag == ["--urdf", "--root", "--tip", "--joint-topic", "--measure-topic", "--measure", "--still-window-s",
                   "--still-speed-rad-s", "--time", "--sigma-m", "--sigma-rad", "--effort-scale", "--effort-offset",
                   "--effort-mix", "--effort-joints", "--effort-units", "--position-scale", "--position-offset",
                   "--position-mix", "--target", "--camera-on",
                   "--clock-offset-bound-s"]
    assert not set(bag) & set(panels["Options"])
    assert "--force" in panels["Options"] and "--strict" in panels["Options"]


def test_view_binds_the_viewer_to_this_machine_unless_told(tmp_path):
    (tmp_path / "run.rrd").write_bytes(b"")  # only its presence matters: --print opens nothing
    load_commands()
    runner = CliRunner()
    res = runner.invoke(app, ["view", str(tmp_path), "--print"])
    assert res.exit_code == 0, res.output
    assert res.output.splitlines()[-1].endswith(f"rerun --bind 127.0.0.1 {tmp_path / 'run.rrd'}")
    res = runner.invoke(app, ["view", str(tmp_path), "--print", "--bind", "0.0.0.0"])
    assert res.output.splitlines()[-1].endswith(f"rerun --bind 0.0.0.0 {tmp_path / 'run.rrd'}")


def test_shell_completion_completes_commands_and_options():
    """The installed command answers the shell's completion requests (click's protocol, what
    `--install-completion` sets up): command names, and a command's options."""
    import os
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    exe = shutil.which("robocal", path=str(Path(sys.executable).parent))
    assert exe, "robocal is not installed next to this interpreter"
    env = {**os.environ, "_ROBOCAL_COMPLETE": "complete_bash", "COMP_WORDS": "robocal ru", "COMP_CWORD": "1"}
    out = subprocess.run([exe], env=env, capture_output=True, text=True, check=True).stdout.split()
    assert out == ["run"]
    env |= {"COMP_WORDS": "robocal run x --still-w", "COMP_CWORD": "3"}
    out = subprocess.run([exe], env=env, capture_output=True, text=True, check=True).stdout.split()
    assert out == ["--still-window-s"]
    res = CliRunner().invoke(app, ["--help"])
    assert "--install-completion" in res.output and "--show-completion" in res.output
