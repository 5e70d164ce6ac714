"""Write docs/reference/cli.md from the `robocal` command line itself: every command's and subcommand's
`--help`, as the installed command prints it (100 columns, no colour).

    python docs/reference/gen_cli.py            # rewrite docs/reference/cli.md
    python docs/reference/gen_cli.py --check    # exit 1 if docs/reference/cli.md is not what the CLI prints

`tests/test_cli_reference.py` runs the check, so the reference cannot drift from the commands.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

OUT = Path(__file__).resolve().parent / "cli.md"
WIDTH = 100


def _commands():
    """(path of words, click command) for the root, every command and every subcommand, in help order."""
    import typer

    from pipeline.cli import app, load_commands

    load_commands(None)
    root = typer.main.get_command(app)

    def walk(cmd, words):
        yield words, cmd
        if hasattr(cmd, "list_commands"):  # a group (typer bundles its own click)
            ctx = cmd.context_class(cmd, info_name=" ".join(["robocal", *words]))
            for name in cmd.list_commands(ctx):
                sub = cmd.get_command(ctx, name)
                if sub is not None and not getattr(sub, "hidden", False):
                    yield from walk(sub, [*words, name])

    return root, list(walk(root, []))


def render() -> str:
    """The whole reference page, deterministic for a given CLI."""
    os.environ.update({"COLUMNS": str(WIDTH), "TERM": "dumb", "NO_COLOR": "1"})
    os.environ.pop("FORCE_COLOR", None)
    from typer.testing import CliRunner

    from pipeline.cli import app

    _, cmds = _commands()
    runner = CliRunner()
    lines = ["# Command-line reference (`robocal`)", "",
             "Generated from the commands' own `--help` by `python docs/reference/gen_cli.py`; do not edit by hand",
             "(`tests/test_cli_reference.py` checks it is current). How to use them: [the user guide](../README.md).",
             "", "| command | what it does |", "|---|---|"]
    for words, cmd in cmds[1:]:
        name = " ".join(words)
        short = (cmd.get_short_help_str(limit=120) or "").replace("|", "\\|")
        anchor = "robocal-" + "-".join(words)
        lines.append(f"| [`robocal {name}`](#{anchor}) | {short} |")
    lines.append("")
    for words, _cmd in cmds:
        res = runner.invoke(app, [*words, "--help"], prog_name="robocal", terminal_width=WIDTH,
                            env={"COLUMNS": str(WIDTH), "TERM": "dumb", "NO_COLOR": "1"})
        if res.exit_code != 0:
            raise SystemExit(f"robocal {' '.join(words)} --help exited {res.exit_code}: {res.output}")
        text = "\n".join(line.rstrip() for line in res.output.strip("\n").splitlines())
        lines += [f"## robocal {' '.join(words)}".rstrip(), "", "```text", text, "```", ""]
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    text = render()
    if "--check" in argv:
        if not OUT.exists() or OUT.read_text() != text:
            print(f"{OUT} is not what the CLI prints: run `python docs/reference/gen_cli.py`", file=sys.stderr)
            return 1
        return 0
    OUT.write_text(text)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
