"""Nonsense at the door, and recordings no command may replace: the classes ``options`` and ``outputs``
of tests/fuzz_surfaces.py (run by tests/test_fuzz.py and benchmarks/bench_fuzz.py --surfaces).

``options``: a command line that names real files but asks for nonsense — one CSV column feeding two
quantities (twice in --position-cols, in two --tip, a joint's own column as a position), --tip with
--position-cols, a --coupled joint with its own column, a prismatic joint coupled to a revolute one
without the factor's unit, coupling factors of 1e7 and 1e308, a unit that does not match the joints,
payloads 10⁹ m away, heavier than the robot or on a link that loads nothing, a ROS 2 bag measuring
x = 1e300.  Every one must be refused (one line): a success is the failure ``accepted-nonsense``.

``outputs``: an existing recording at the output of every command that writes one (import csv /
ros2 / images, simulate urdf / arc-welder / delta-tracker / scorbot-scanner / fleet, recover,
acquire), without --force, with --force over an existing .bak, or a recording of real measurements
(acquired, or cut short) with --force: refused, the recording and its .bak byte for byte.

Each case runs the command in process (typer's CliRunner) on a small robot written here: PR6 of
tests/test_urdf_simulate.py (a prismatic torso lift and six revolute joints) with link masses.
"""

from __future__ import annotations

import functools
import shutil
from pathlib import Path

import numpy as np

JOINTS = ["torso_lift", "arm_1", "arm_2", "arm_3", "arm_4", "arm_5", "arm_6"]
LIMITS = [(0, 0.35), (0, 2.7), (-1.5, 1.0), (-3.4, 1.5), (-0.3, 2.3), (-2.0, 2.0), (-1.4, 1.4)]
TIP = ("--root", "base", "--tip", "flange", "--measure", "point")
MARKER_ARGS = ("--position-cols", "x1,y1,z1")
TWO = ("--root", "base", "--measure", "point")
OPTIONS = [  # (command, its arguments after the files): each is nonsense
    ("csv", TIP + ("--position-cols", "x1,x1,z1")),
    ("csv", TWO + ("--tip", "flange=x1,x1,x1")),
    ("csv", TIP + ("--position-cols", "x1,y1,arm_1")),
    ("csv", TWO + ("--tip", "flange=x1,y1,z1", "--tip", "a5=x1,y1,z1")),
    ("csv", TIP + ("--position-cols", "x1,y1,z1", "--coupled", "arm_6=arm_5")),
    ("csv", TIP + ("--position-cols", "x1,y1,z1", "--coupled", "torso_lift=arm_1", "--coupling-wins")),
    ("csv", TWO + ("--tip", "flange=x1,y1,z1", "--tip", "a5=x2,y2,z2", "--position-cols", "x1,y1,z1")),
    ("csv", TIP + ("--position-cols", "x1,y1,z1", "--coupled", "arm_6=1e308*arm_5", "--coupling-wins")),
    ("csv", TIP + ("--position-cols", "x1,y1,z1", "--coupled", "arm_6=1e7*arm_5", "--coupling-wins")),
    ("csv", TIP + ("--position-cols", "x1,y1,z1", "--coupled", "arm_6=0.5[m/rad]*arm_5", "--coupling-wins")),
    ("run", ("--payload", "2@a6:0,0,1e9")),
    ("run", ("--payload", "900@a6")),
    ("run", ("--payload", "2@base")),
    ("ros2", ()),
]
OUTPUTS = ("import csv", "import ros2", "import images", "simulate urdf", "simulate arc-welder",
           "simulate delta-tracker", "simulate scorbot-scanner", "simulate fleet", "recover", "acquire",
           "--force over a .bak", "--force over an acquisition", "--force over a recording cut short")


def urdf_text() -> str:
    """PR6 with a 2 kg link mass on each of its moving links (gravity terms and payloads need masses)."""
    from test_urdf_simulate import PR6

    text = PR6
    for link in ("torso", "a1", "a2", "a3", "a4", "a5", "a6"):
        text = text.replace(f'<link name="{link}"/>', f'<link name="{link}"><inertial><mass value="2"/>'
                            '<origin xyz="0 0 0.05"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" '
                            'iyz="0"/></inertial></link>')
    return text


@functools.cache
def robot(base: Path) -> tuple[Path, Path, Path]:
    """(URDF, CSV of 12 postures with two markers x1..z2, the recording imported from it) under `base`."""
    rng = np.random.default_rng(7)
    d = base / "robot"
    d.mkdir(parents=True, exist_ok=True)
    u = d / "pr6.urdf"
    u.write_text(urdf_text())
    q = np.column_stack([rng.uniform(lo, hi, 12) for lo, hi in LIMITS])
    m = rng.uniform(-0.5, 0.5, (12, 6))
    rows = [",".join(JOINTS + ["x1", "y1", "z1", "x2", "y2", "z2"])]
    rows += [",".join(repr(float(v)) for v in r) for r in np.column_stack([q, m])]
    csv = d / "postures.csv"
    csv.write_text("\n".join(rows) + "\n")
    rec = d / "pr6.mcap"
    invoke(["import", "csv", str(csv), "--urdf", str(u), *TIP, "--position-cols", "x1,y1,z1", "--out", str(rec)])
    return u, csv, rec


def invoke(args: list[str]) -> None:
    """`robocal ARGS` in this process; its RobocalError (or any other exception) raised here."""
    from typer.testing import CliRunner

    from pipeline.cli import app, load_commands

    load_commands(args)
    r = CliRunner().invoke(app, args)
    if r.exception is not None and not isinstance(r.exception, SystemExit):
        raise r.exception
    if r.exit_code:
        raise RuntimeError(f"exit {r.exit_code}: {r.output[-300:]}")


def _bag(d: Path, x: float) -> Path:
    import independent_joint_bag as jb

    rng = np.random.default_rng(3)
    q = np.column_stack([rng.uniform(lo + 0.05, hi - 0.05, 6) for lo, hi in LIMITS])
    markers = rng.uniform(-0.5, 0.5, (6, 3))
    markers[2, 0] = x
    return jb.write_bag(d / "bag", JOINTS, q, np.ones_like(q), {"/mocap/flange": markers})


def options_case(k: int, base: Path):
    """The k-th nonsense command line (cyclic): make(d) for `fuzz_surfaces.SurfaceCase`."""
    command, extra = OPTIONS[k % len(OPTIONS)]

    def make(d: Path):
        u, csv, rec = robot(base)
        out = d / "out.mcap"
        if command == "csv":
            args = ["import", "csv", str(csv), "--urdf", str(u), *extra, "--out", str(out)]
        elif command == "run":
            args = ["run", str(rec), "--out", str(d / "run"), *extra]
        else:
            args = ["import", "ros2", str(_bag(d, 1e300)), "--urdf", str(u), *TIP[:4], "--out", str(out)]
        return (lambda: invoke(args)), [], {p: p.read_bytes() for p in (u, csv, rec)}
    return make


def _acquired(path: Path) -> None:
    from pipeline.recording.output import ACQUIRED
    from pipeline.recording.writer import RecordingWriter

    with RecordingWriter(path, origin=ACQUIRED) as w:
        w.metadata("robocal.campaign", {"system": "arc-welder"})


def outputs_case(k: int, base: Path):
    """The k-th command writing over an existing recording (cyclic): make(d)."""
    what = OUTPUTS[k % len(OUTPUTS)]

    def make(d: Path):
        from hostile_support import BUNDLED
        from pipeline.fleet.simulate import FleetSpec, campaign_path

        u, csv, rec = robot(base)
        out = d / "rec.mcap"
        shutil.copy(BUNDLED["delta-tracker"], out)  # a recording robocal wrote, of another robot
        user = [out]
        imp = ["import", "csv", str(csv), "--urdf", str(u), *TIP, "--position-cols", "x1,y1,z1", "--out", str(out)]
        sim = ["--out", str(out)]
        args = {"import csv": imp,
                "import ros2": ["import", "ros2", str(d / "no-bag"), "--urdf", str(u), *TIP[:4], "--out", str(out)],
                "import images": ["import", "images", str(d), "--target", "chessboard:9x6:0.02", "--joints",
                                  str(csv), "--urdf", str(u), "--root", "base", "--tip", "flange", "--out", str(out)],
                "simulate urdf": ["simulate", "urdf", "--urdf", str(u), "--root", "base", "--tip", "flange", *sim],
                "simulate arc-welder": ["simulate", "arc-welder", *sim],
                "simulate delta-tracker": ["simulate", "delta-tracker", *sim],
                "simulate scorbot-scanner": ["simulate", "scorbot-scanner", *sim],
                "recover": ["recover", str(rec), str(out)],
                "acquire": ["acquire", "--device", f"bridge={d / 'no-port'}", "--out", str(out)],
                "--force over a .bak": imp + ["--force"],
                "--force over an acquisition": imp + ["--force"],
                "--force over a recording cut short": imp + ["--force"]}.get(what)
        if what == "simulate fleet":
            arch = d / "archive"
            first = campaign_path(arch, FleetSpec(robots=1, months=1), 0, 1)
            first.parent.mkdir(parents=True)
            shutil.move(out, first)
            user = [first]
            args = ["simulate", "fleet", "--robots", "1", "--months", "1", "--out", str(arch)]
        elif what == "--force over a .bak":
            user.append(out.with_name("rec.mcap.bak"))
            shutil.copy(BUNDLED["scorbot-scanner"], user[-1])
        elif what == "--force over an acquisition":
            out.unlink()
            _acquired(out)
        elif what == "--force over a recording cut short":
            out.write_bytes(BUNDLED["arc-welder-touch"].read_bytes()[:50_000])
        return (lambda: invoke(args)), [user[0]], {p: p.read_bytes() for p in user}
    return make
