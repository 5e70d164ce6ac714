"""The `robocal` command line (typer).  Errors in the user's input become one line and exit 2."""

from __future__ import annotations

import sys

import typer
from rich.console import Console

# The help panels of `robocal --help`, by what the user is doing, in this order.
IMPORT = "Import"
CALIBRATE = "Calibrate"
PLAN = "Plan & compensate"
SIMULATE = "Simulate & acquire"
FLEET = "Fleet"
VIEW = "View"
PANELS = (IMPORT, CALIBRATE, PLAN, SIMULATE, FLEET, VIEW)


class _TaskOrderedGroup(typer.core.TyperGroup):
    """A command group that lists its commands panel by panel in the order of `PANELS` (within a
    panel, in the order they were registered), whichever module registered them first."""

    def list_commands(self, ctx) -> list[str]:
        rank = {p: i for i, p in enumerate(PANELS)}
        names = super().list_commands(ctx)
        return sorted(names, key=lambda n: rank.get(getattr(self.commands[n], "rich_help_panel", None), len(PANELS)))


def _flags_take_no_value() -> None:
    """Show a boolean flag in the help as itself (`--force`, `--x/--no-x`), not as `--force <bool>`:
    recent typer prints every option's type in the rich help, a flag's too, though a flag takes no
    value.  Idempotent; a typer without `TyperOption.display_type_rich` is left as it is."""
    cls = getattr(typer.core, "TyperOption", None)
    shown = getattr(cls, "display_type_rich", None)
    if shown is None or getattr(shown, "_flags_take_no_value", False):
        return

    def display_type_rich(self, ctx):
        return None if (self.is_flag or self.count) else shown(self, ctx)

    display_type_rich._flags_take_no_value = True
    cls.display_type_rich = display_type_rich


def _no_emoji() -> None:
    """Help text as written: rich reads ``:name:`` as an emoji code (``A:B:METRES`` became "A🅱METRES"), so
    typer's help renders rich markup with emoji codes off.  Idempotent."""
    import rich.text
    import typer.rich_utils as ru

    if getattr(ru.Text, "_no_emoji", False):
        return

    class Text(rich.text.Text):
        _no_emoji = True

        @classmethod
        def from_markup(cls, text, *, style="", emoji=False, **kw):
            return rich.text.Text.from_markup(text, style=style, emoji=False, **kw)

    ru.Text = Text


_flags_take_no_value()
_no_emoji()
app = typer.Typer(name="robocal", help="Log-centric robot calibration: record, calibrate, inspect.",
                  no_args_is_help=True, pretty_exceptions_enable=False, cls=_TaskOrderedGroup)
simulate_app = typer.Typer(help="Simulate a calibration campaign of a reference system into an MCAP recording.",
                           no_args_is_help=True)
app.add_typer(simulate_app, name="simulate", rich_help_panel=SIMULATE)


def console(stderr: bool = False) -> Console:
    """A rich console that wraps only on a terminal: in CI logs and pipes a line stays one line
    (grep-friendly), whatever the 80-column default."""
    stream = sys.stderr if stderr else sys.stdout
    return Console(stderr=stderr, width=None if stream.isatty() else 10_000, soft_wrap=not stream.isatty(), emoji=False)


err = console(stderr=True)


def force_option(what: str = "recording"):
    """`--force` of a command writing a recording (or a simulation's truth): replace an existing one robocal
    wrote, keeping it as NAME.bak (`pipeline.recording.output`; never a recording of real measurements)."""
    return typer.Option(False, "--force", help=f"Replace an existing {what} robocal wrote, keeping the old one as "
                        "NAME.bak (never a recording robocal acquire made; never over an existing .bak).")


def _version(value: bool) -> None:
    if value:
        from pipeline import __version__

        print(f"robocal {__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="Print robocal's version and exit.")) -> None:
    """Log-centric robot calibration: record, calibrate, inspect."""


SIMULATORS = ("simulate", "sim_camera", "sim_delta", "sim_scanner", "sim_urdf", "fleet")
# The modules that register each command (and what it calls in-process): a command imports only
# these, not all the others' dependencies (every command pays its own imports only).
COMMAND_MODULES: dict[str, tuple[str, ...]] = {
    "acquire": ("acquire",), "recover": ("acquire",), "device-sim": ("acquire", *SIMULATORS),
    "calibrate": ("calibrate",), "evaluate": ("evaluate",), "compensate": ("compensate",), "diagnose": ("diagnose",), "fleet": ("fleet",),
    "import": ("importer", "images", "ros2"), "export": ("export",), "plan": ("plan",), "report": ("report",), "reprocess": ("reprocess",),
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


# Options renamed to carry their unit: the old names stay accepted (hidden from --help, one warning line) so
# the scripts written for them keep working.
RENAMED = {"--f-scale": "--f-scale-m", "--still-window": "--still-window-s", "--still-speed": "--still-speed-rad-s",
           "--clock-offset-bound": "--clock-offset-bound-s", "--clock-offset": "--clock-offset-s"}


def renamed(argv: list[str]) -> tuple[list[str], list[str]]:
    """(`argv` with each renamed option's old name, alone or as ``--old=VALUE``, replaced by its new name;
    the old names met).  Words after ``--`` are left as they are."""
    out, met = [], []
    for i, a in enumerate(argv):
        if a == "--":
            return out + argv[i:], met
        name, eq, value = a.partition("=")
        if name in RENAMED:
            met.append(name)
            a = RENAMED[name] + eq + value
        out.append(a)
    return out, met


def main() -> None:
    """Console-script entry point."""
    from rich.markup import escape  # an error quotes the user's text ("[m/rad]", a path with brackets) as written

    from pipeline.errors import RobocalError

    sys.argv[1:], old = renamed(sys.argv[1:])
    for name in old:
        err.print(f"[yellow]warning:[/] {name} is now {RENAMED[name]} (the old name still works)", highlight=False,
                  soft_wrap=True)
    load_commands(sys.argv[1:])

    from typer._click.exceptions import UsageError

    try:
        code = app(standalone_mode=False)
    except UsageError as e:  # an unknown choice, a missing option: one line, exit 2, like every bad input
        if not e.format_message().strip():  # no arguments: the help was printed
            sys.exit(e.exit_code)
        cmd = e.ctx.command_path if e.ctx is not None else "robocal"
        message = e.format_message().replace("Value error, ", "")  # the validator's prefix says nothing to a user
        err.print(f"[bold red]robocal: error:[/] {escape(message)} (see {escape(cmd)} --help)",
                  highlight=False, soft_wrap=True)
        sys.exit(2)
    except RobocalError as e:
        err.print(f"[bold red]robocal: error:[/] {escape(str(e))}", highlight=False, soft_wrap=True)
        sys.exit(2)
    except PermissionError as e:  # an output folder the user cannot write: one line, not a traceback
        err.print(f"[bold red]robocal: error:[/] {escape(str(e.filename))}: cannot write (PermissionError: {e.strerror})",
                  highlight=False, soft_wrap=True)
        sys.exit(2)
    except OSError as e:  # a file system error on a path the user named: one line, not a traceback
        err.print(f"[bold red]robocal: error:[/] {escape(str(e.filename or ''))}: {type(e).__name__}: "
                  f"{escape(str(e.strerror or e))}",
                  highlight=False, soft_wrap=True)
        sys.exit(2)
    if isinstance(code, int) and code:  # typer.Exit(code) from a command (--strict, …)
        sys.exit(code)
