"""The `robocal` command line (typer).  Errors in the user's input become one line and exit 2."""

from __future__ import annotations

import sys

import typer
from rich.console import Console

app = typer.Typer(name="robocal", help="Log-centric robot calibration: record, calibrate, inspect.",
                  no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False)
simulate_app = typer.Typer(help="Simulate a calibration campaign of a reference system into an MCAP recording.",
                           no_args_is_help=True)
app.add_typer(simulate_app, name="simulate")

def console(stderr: bool = False) -> Console:
    """A rich console that wraps only on a terminal: in CI logs and pipes a line stays one line
    (grep-friendly), whatever the 80-column default."""
    stream = sys.stderr if stderr else sys.stdout
    return Console(stderr=stderr, width=None if stream.isatty() else 10_000, soft_wrap=not stream.isatty())


err = console(stderr=True)


def _version(value: bool) -> None:
    if value:
        from pipeline import __version__

        print(f"robocal {__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="Print robocal's version and exit.")) -> None:
    """Log-centric robot calibration: record, calibrate, inspect."""


SIMULATORS = ("simulate", "sim_delta", "sim_scanner", "sim_urdf", "fleet")
# The modules that register each command (and what it calls in-process): a command imports only
# these, not all the others' dependencies (every command pays its own imports only).
COMMAND_MODULES: dict[str, tuple[str, ...]] = {
    "acquire": ("acquire",), "recover": ("acquire",), "device-sim": ("acquire", *SIMULATORS),
    "calibrate": ("calibrate",), "compensate": ("compensate",), "diagnose": ("diagnose",), "fleet": ("fleet",),
    "import": ("importer", "images", "ros2"), "plan": ("plan",), "report": ("report",), "reprocess": ("reprocess",),
    "run": ("run",), "ingest": ("run",), "validate": ("run",), "identify": ("run",), "observe": ("run",),
    "simulate": SIMULATORS, "view": ("view",),
}


def load_commands(argv: list[str] | None = None) -> None:
    """Import the modules that register the command `argv` names (its first word), or every module of
    this package (no command, an option such as --help, an unknown name): each registers its commands
    on `app`/`simulate_app`."""
    import importlib
    import pkgutil

    import pipeline.cli as pkg

    name = argv[0] if argv else None
    names = COMMAND_MODULES.get(name) if name else None
    if names is None:
        names = tuple(m.name for m in pkgutil.iter_modules(pkg.__path__))
    for m in sorted(names):
        importlib.import_module(f"pipeline.cli.{m}")


def main() -> None:
    """Console-script entry point."""
    from pipeline.errors import RobocalError

    load_commands(sys.argv[1:])

    try:
        app()
    except RobocalError as e:
        err.print(f"[bold red]robocal: error:[/] {e}", highlight=False, soft_wrap=True)
        sys.exit(2)
    except PermissionError as e:  # an output folder the user cannot write: one line, not a traceback
        err.print(f"[bold red]robocal: error:[/] {e.filename}: cannot write (PermissionError: {e.strerror})",
                  highlight=False, soft_wrap=True)
        sys.exit(2)
    except OSError as e:  # a file system error on a path the user named: one line, not a traceback
        err.print(f"[bold red]robocal: error:[/] {e.filename or ''}: {type(e).__name__}: {e.strerror or e}",
                  highlight=False, soft_wrap=True)
        sys.exit(2)
