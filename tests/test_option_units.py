"""Options are SI with the unit in their name (m, rad, s): `simulate urdf --noise-m/--error-m/--error-rad/--noise-rad`
give the same campaign, byte for byte, as the older millimetre and degree spellings kept as hidden aliases."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
from conftest import run_cli
from r6_robot import URDF

REPO = Path(__file__).resolve().parents[1]


def test_si_options_equal_the_mm_deg_aliases(tmp_path):
    urdf = tmp_path / "r6.urdf"
    urdf.write_text(URDF)
    common = ("simulate", "urdf", "--urdf", urdf, "--root", "b", "--tip", "l6", "--measure", "pose",
              "--poses", "12", "--seed", "3")
    si = run_cli(*common, "--error-m", "0.002", "--error-rad", str(np.radians(0.3)), "--noise-m", "5e-5",
                 "--noise-rad", str(np.radians(0.02)), "--out", tmp_path / "si.mcap", "--truth", tmp_path / "si.json")
    old = run_cli(*common, "--error-mm", "2", "--error-deg", "0.3", "--noise-mm", "0.05", "--noise-deg", "0.02",
                  "--out", tmp_path / "old.mcap", "--truth", tmp_path / "old.json")
    assert si.returncode == 0 and old.returncode == 0, si.stderr + old.stderr
    assert (tmp_path / "si.json").read_text() == (tmp_path / "old.json").read_text()
    assert (tmp_path / "si.mcap").read_bytes() == (tmp_path / "old.mcap").read_bytes()
    default = run_cli(*common, "--out", tmp_path / "d.mcap", "--truth", tmp_path / "d.json")
    assert default.returncode == 0 and (tmp_path / "d.json").read_text() != (tmp_path / "si.json").read_text()
    assert "--noise-mm" not in run_cli("simulate", "urdf", "--help").stdout


# ----- CLI conventions: no emoji mangling, choices typed as choices, units in names, old names kept ----------
@functools.lru_cache(maxsize=1)
def _helps() -> dict[str, str]:
    """Every command's --help text, rendered as the user sees it (typer's rich help, wide)."""
    import typer
    from typer.testing import CliRunner

    from pipeline.cli import app, load_commands
    from test_cli_help import _walk

    load_commands()
    runner = CliRunner()
    out = {}
    for path, _ in _walk(typer.main.get_command(app)):
        res = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "300"}, terminal_width=300)
        assert res.exit_code == 0, (path, res.output)
        out[" ".join(path) or "robocal"] = res.output
    return out


def test_no_emoji_in_any_help():
    """rich reads ``:name:`` as an emoji code (``A:B:METRES`` became "A🅱METRES"): no command's help holds a
    character of the emoji / pictograph blocks, and the texts that carry colons come out as written."""
    import re

    helps = _helps()
    emoji = re.compile("[\U0001F000-\U0001FAFF\u2600-\u27BF\u2B00-\u2BFF]")
    bad = {cmd: emoji.findall(text) for cmd, text in helps.items() if emoji.search(text)}
    assert not bad, bad
    assert "A:B:METRES" in helps["import csv"]


CHOICES = {"run": {"--loss": "linear|huber|soft_l1", "--registration": "shared|per-recording",
                   "--model-choice": "auto|groups|shrinkage", "--camera-on": "tip|world", "--time": "header|log",
                   "--measure": "point|pose|effort"},
           "calibrate": {"--loss": "linear|huber|soft_l1", "--solver": "lm|ga", "--model-choice": "auto|groups|shrinkage"},
           "import ros2": {"--camera-on": "tip|world", "--lens": "pinhole|fisheye", "--effort-units": "Nm|raw"},
           "import csv": {"--measure": "point|pose|plane|coincidence|effort", "--joint-units": "rad|deg",
                          "--length-units": "m|mm", "--orientation": "rpy|quat"},
           "import images": {"--camera-on": "tip|world", "--lens": "pinhole|fisheye"},
           "evaluate": {"--refit": "none|registration"}, "reprocess": {"--engine": "dask|processes|serial"}}


def test_choice_options_are_typed_as_choices_and_dimensioned_ones_carry_their_unit():
    """A choice shows its values (validated, completed by the shell) instead of <str>; an option with a
    dimension carries its unit in its name; the old unit-less names are hidden; each default is shown one way
    (typer's [default: …], not repeated in the text)."""
    import re

    helps = _helps()
    for cmd, opts in CHOICES.items():
        for opt, values in opts.items():
            assert re.search(rf"{re.escape(opt)}\s+<{re.escape(values)}>", helps[cmd]), (cmd, opt, values)
    for cmd, opts in {"run": ("--f-scale-m", "--still-window-s", "--still-speed-rad-s", "--clock-offset-bound-s"),
                      "import ros2": ("--still-window-s", "--still-speed-rad-s", "--clock-offset-bound-s",
                                      "--clock-offset-s")}.items():
        for opt in opts:
            assert opt in helps[cmd], (cmd, opt)
        for old in ("--f-scale ", "--still-window ", "--still-speed ", "--clock-offset-bound ", "--clock-offset "):
            assert old not in helps[cmd], (cmd, old)
    assert "[default: (linear)]" in helps["run"] and "(default linear)" not in helps["run"]  # typer: (…) a default set later


def test_old_option_names_still_work(tmp_path):
    """The renamed options' old names are read as the new ones (one warning line): a script written for
    `--f-scale` runs as with `--f-scale-m`; an unknown choice is one line, exit 2."""
    from pipeline.cli import RENAMED, renamed

    argv, met = renamed(["run", "R.mcap", "--f-scale", "1e-4", "--still-window=0.5", "--", "--clock-offset"])
    assert argv == ["run", "R.mcap", "--f-scale-m", "1e-4", "--still-window-s=0.5", "--", "--clock-offset"]
    assert met == ["--f-scale", "--still-window"] and set(RENAMED.values()) == {
        "--f-scale-m", "--still-window-s", "--still-speed-rad-s", "--clock-offset-bound-s", "--clock-offset-s"}
    rec = REPO / "recordings" / "arc-welder-touch.mcap"
    p = run_cli("run", rec, "--f-scale", "2e-4", "--stages", "ingest", "--out", tmp_path / "run")
    assert p.returncode == 0, p.stderr
    assert "--f-scale is now --f-scale-m" in p.stderr
    p = run_cli("run", rec, "--loss", "cauchy", "--out", tmp_path / "run2")
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert p.returncode == 2 and len(lines) == 1 and "'cauchy' is not one of" in lines[0], p.stderr
