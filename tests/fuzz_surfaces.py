"""A seeded corpus of hostile inputs beyond robocal's own recordings: CSV tables, URDFs, ROS 2 bags
(written by rosbags' own writer, then cut or bit-flipped), campaign files, compensation targets (an
unknown column, joints in degrees), run folders holding a user's files, reprocess archives, recordings
whose measurement topic is missing or whose times run backwards, absurd counts on the command line,
figures of a few equal values, nonsense options and recordings at an output path (tests/fuzz_door.py).
Used by tests/test_fuzz.py (bounded) and benchmarks/bench_fuzz.py --surfaces.

Each case runs in this process and is classified: `error` (one-line `RobocalError` naming the
file), `ok`, `warned` (success that says what it lost), or a failure: `traceback`, `hang`,
`memory`, `unnamed-error`, `user-data-changed` (a file the user wrote changed or deleted),
`accepted-nonsense` (a case that must be refused succeeded).
"""

from __future__ import annotations

import functools
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import fuzz_door
from fuzz_edits import ARM, TOKENS, csv_bytes, csv_edit, flips, urdf_edit
from hostile_support import BUNDLED, rebuild

SURFACES = ("csv", "urdf", "ros2bag", "campaign", "targets", "runfolder", "archive", "recording", "counts", "figures",
            "options", "outputs")
FAILURES = ("traceback", "hang", "memory", "unnamed-error", "user-data-changed", "accepted-nonsense")
@dataclass(frozen=True)
class SurfaceCase:
    cls: str
    name: str
    make: Callable[[Path], tuple[Callable[[], object], list[Path], dict[Path, bytes]]]
    # make(dir) -> (action, paths an error must name (any one), the user's files that must survive unchanged)
    refuse: bool = False  # nonsense or a file that must not be replaced: a success is `accepted-nonsense`


class _Hang(Exception):
    pass


def classify(case: SurfaceCase, d: Path, timeout_s: float = 60.0) -> tuple[str, str]:
    from pipeline.errors import RobocalError

    d.mkdir(parents=True, exist_ok=True)
    action, named, user = case.make(d)

    def alarm(*_):
        raise _Hang()

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout_s)
    try:
        result = action()
        outcome, detail = ("warned", str(result)[:200]) if result else ("ok", "")
    except RobocalError as e:
        msg = str(e)
        ok = "\n" not in msg and (not named or any(str(p) in msg for p in named))
        outcome, detail = ("error" if ok else "unnamed-error"), msg[:300]
    except _Hang:
        outcome, detail = "hang", f"over {timeout_s} s"
    except MemoryError:
        outcome, detail = "memory", "MemoryError"
    except Exception as e:  # noqa: BLE001 — exactly what the classification is about
        import traceback
        outcome, detail = "traceback", "".join(traceback.format_exception(e))[-1500:]
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    changed = [p for p, b in user.items() if not p.is_file() or p.read_bytes() != b]
    if changed:
        return "user-data-changed", f"{changed[0]} ({outcome}: {detail[:200]})"
    if case.refuse and outcome in ("ok", "warned"):
        return "accepted-nonsense", f"{case.name}: {detail[:200]}"
    return outcome, detail


# ----- shared inputs, made once per process ---------------------------------------------------------
@functools.cache
def _base() -> Path:
    return Path(tempfile.mkdtemp(prefix="robocal-fuzz-surfaces-"))


@functools.cache
def _bag(storage: str = "mcap") -> Path:
    from pipeline.models import urdf
    from pipeline.simulate.ros2_bag import simulate_bag
    from test_urdf_simulate import R6T

    out = _base() / f"bag-{storage}"
    simulate_bag(out, urdf.parse(R6T, "b", "tcp"), n=40, seed=5, storage=storage)  # 3 chunks
    return out


@functools.cache
def _plan() -> Path:
    out = _base() / "plan.json"
    p = subprocess.run([str(Path(sys.executable).parent / "robocal"), "plan", "arc-welder", "--candidates", "80",
                        "--select", "30", "--out", str(out)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return out


@functools.cache
def _run_folder() -> Path:
    from pipeline.stages.runner import run_pipeline

    out = _base() / "run"
    run_pipeline(BUNDLED["delta-tracker"], out, stages=["ingest", "validate"])
    return out


def _write(p: Path, b: bytes) -> Path:
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_bytes(b)
    return p


def _user(*paths: Path) -> dict[Path, bytes]:
    return {p: p.read_bytes() for p in paths}


# ----- the cases ---------------------------------------------------------------------------------------
def _csv_case(k, rng):
    data = csv_edit(k, rng)

    def make(d):
        from pipeline.importers.csv_table import CsvSpec, read_table
        from pipeline.models import urdf

        p = _write(d / "table.csv", data)
        u = _write(d / "arm.urdf", ARM.encode())
        return (lambda: read_table([p], urdf.read(u, "base", "tip"), CsvSpec("point"))[1].get("import_warnings"),
                [p], _user(p, u))
    return make


def _urdf_case(k, rng):
    data = urdf_edit(k, rng)

    def make(d):
        from pipeline.models import urdf

        p = _write(d / "robot.urdf", data)
        return (lambda: urdf.read(p, "base", "tip") and None), [p], _user(p)
    return make


def _bag_case(k, rng):
    how = k % 5
    frac = float(rng.uniform(0.02, 0.3) if how == 4 else rng.uniform(0.6, 0.999))  # little or most left

    def make(d):
        from pipeline.ros2.points import read_bag
        from pipeline.models import urdf
        from test_urdf_simulate import R6T

        bag = d / "bag"
        shutil.copytree(_bag("sqlite3" if how == 3 else "mcap"), bag)
        f = next(p for p in bag.iterdir() if p.suffix in (".mcap", ".db3"))
        b = f.read_bytes()
        f.write_bytes(flips(b, rng, int(rng.integers(1, 17))) if how == 2 else b[: int(len(b) * frac)])
        if how == 1:
            (bag / "metadata.yaml").unlink()
        return (lambda: read_bag(bag, urdf.parse(R6T, "b", "tcp"))[1].get("import_warnings")), [bag], _user(f)
    return make


def _campaign_case(k, rng):
    how = k % 7

    def make(d):
        from pipeline.plan import campaign

        p = d / "campaign.json"
        if how == 0:
            _write(p, b'{"a":' * 100_000 + b"1" + b"}" * 100_000)
        else:
            doc = json.loads(_plan().read_text())
            if how == 1:
                doc["controller"][("rate_hz", "dwell_s", "search_speed_m_s", "joint_speed_rad_s")[k % 4]] = (
                    1e308, 1e300, 1e-300, 1e-300)[k % 4]
            elif how == 2:
                m = doc["measurements"][int(rng.integers(len(doc["measurements"])))]
                m[sorted(m)[int(rng.integers(len(m)))]] = [None, "x", 1e308, {"a": []}][k % 4]
            elif how == 3:
                doc["system"] = "delta-tracker"
            text = json.dumps(doc).encode()
            if how == 4:
                text = text[: int(rng.integers(0, len(text)))]
            elif how == 5:
                text = flips(text, rng, int(rng.integers(1, 9)))
            elif how == 6:
                text = text.replace(b'"touch"', b'"t\xe9uch"')
            _write(p, text)
        return (lambda: campaign.read(p, "arc-welder") and None), [p], _user(p)
    return make


def _targets_case(k, rng):
    rows = [["x", "y", "z", "name"]] + [[repr(float(v)) for v in rng.uniform(-1, 1, 3)] + [f"t{i}"] for i in range(6)]
    how = k % 9
    i, j = int(rng.integers(1, len(rows))), int(rng.integers(0, 3))
    if how >= 6:  # nonsense a reader used to take: an unknown column, joints in degrees, some joints only
        rows[0] += [["comment", "q_j1", "q_j2"][how - 6]] + (["q_j2"] if how == 7 else [])
        for r in rows[1:]:
            r += [["a", "90.0", "0.5"][how - 6]] + (["45.0"] if how == 7 else [])
    if how == 0:
        rows[0][1] = "x"
    elif how == 1:
        rows[i][j] = ("1e308", "0_5", "nan", "")[k % 4]
    elif how == 2:
        rows[i][j] = TOKENS[int(rng.integers(len(TOKENS)))]
    data = csv_bytes(rows)
    if how == 3:
        data = data[:5] + b"\xe9" + data[5:]
    elif how == 4:
        data = flips(data, rng, int(rng.integers(1, 9)))
    elif how == 5:
        data = data[: int(rng.integers(0, len(data)))]

    def make(d):
        from pipeline.compensate.program import read_targets

        p = _write(d / "targets.csv", data)
        ranges = (np.array([-3.0, -2.0]), np.array([3.0, 2.0]), np.array([True, True]))
        return (lambda: read_targets(p, ["j1", "j2"], ranges) and None), [p], _user(p)
    return make


def _runfolder_case(k, rng):
    how = k % 7

    def make(d):
        from pipeline.compensate.program import load_run
        from pipeline.stages.runner import run_pipeline

        run = d / "run"
        shutil.copytree(_run_folder(), run)
        user: list[Path] = []
        named = [run]
        if how == 0:  # the user's file inside robocal's stage folder, then --force
            user.append(_write(run / ("ingest", "validate")[k % 2] / "notes.txt", b"mine"))
        elif how == 1:  # a user's folder that looks like an old run folder
            shutil.rmtree(run)
            _write(run / "ingest" / "stage.json", b'{"stage": "ingest", "outputs": {}}')
            user += [_write(run / "ingest" / "thesis.tex", b"three years"), _write(run / "results.json", b"{}")]
        elif how == 2:
            f = _write(run / "identify" / "fit.json", [b"{", b"[1]", b'{"names": 3}', b"\xff"][k % 4])
            named = [f]
            return (lambda: load_run(run) and None), named, _user(f)
        elif how == 3:  # robocal's own files damaged
            _write(run / "ingest" / "stage.json", [b"{", b'{"a":' * 50_000 + b"}" * 50_000, b"[]"][k % 3])
        elif how == 4:
            _write(run / "ingest" / ".robocal-stage", flips((run / "ingest" / ".robocal-stage").read_bytes(), rng, 8))
            user.append(_write(run / "ingest" / "mine.csv", b"a,b\n"))
        elif how == 5:
            user.append(_write(run / "validate" / "sub" / "deep" / "plot.png", b"\x89PNG"))
        else:
            os.symlink("/etc/hostname", run / "ingest" / "link")
        return (lambda: run_pipeline(BUNDLED["delta-tracker"], run, stages=["ingest", "validate"], force=how != 3)
                and None), named, _user(*user)
    return make


def _archive_case(k, rng):
    how = k % 5

    def make(d):
        from pipeline.fleet.engine import config_of, plan
        from pipeline.fleet.rows import empty_row, gate

        arch = d / "archive"
        rec = arch / "robot" / "a.mcap"
        rec.parent.mkdir(parents=True)
        shutil.copy(BUNDLED["delta-tracker"], rec)
        exp = rec.with_name("a.expected.json")
        user = [rec]
        if how == 0:
            _write(exp, b'{"a":' * 100_000 + b"1" + b"}" * 100_000)
        elif how == 1:
            _write(exp, [b"{", b"\xff\xfe", b"[1, 2]", b'{"rms_after_m": "x"}'][k % 4])
        elif how == 2:
            os.symlink(arch, arch / "robot" / "loop")
            os.symlink("/", arch / "escape")
        elif how == 3:
            shutil.copy(rec, arch / "robot" / "new\nline.mcap")
            (arch / "robot" / "new\nline.mcap").write_bytes(rec.read_bytes()[:999])
        else:
            _write(arch / "robot" / "b.mcap", flips(rec.read_bytes(), rng, 16))
        if exp.exists():
            user.append(exp)

        def act():
            tasks, _, skipped = plan(arch, d / "out")
            for t in tasks:
                row = empty_row(t.found.rel, str(t.found.path), "", 0, config_of(None, None), str(t.run_dir))
                row["status"] = "pass"
                gate(row, t.found.path)
            return skipped
        return act, [arch], _user(*user)
    return make


def _recording_case(k, rng):
    how = k % 4
    src = BUNDLED["arc-welder-touch" if how >= 2 else "delta-tracker"]

    def make(d):
        from hostile_support import edit_json
        from pipeline.recording.schemas import META_CAMPAIGN
        from pipeline.stages.runner import run_pipeline

        p = d / "rec.mcap"
        if how == 0:
            topic = ["/../../x", "/" + "t" * 300, "/po\x00int", "/mesure\u00e9", "/touch/contact"][int(rng.integers(5))]
            rebuild(src, p, channel=lambda t: {"topic": topic} if t == "/tracker/point" else {})
        elif how == 1:
            rebuild(src, p, meta=lambda md: list({**md, META_CAMPAIGN: {**md[META_CAMPAIGN], "system": (
                "arc-welder", "scorbot-scanner", "urdf")[k % 3]}}.items()))
        else:
            i = int(rng.integers(0, 20))
            shift = -(10 ** int(rng.integers(9, 19)))
            rebuild(src, p, msg=edit_json("/touch/contact", i, lambda m: {
                **m, "timestamp_ns": -5 if how == 2 else m["timestamp_ns"] + shift}))
        return (lambda: run_pipeline(p, d / "run", stages=["ingest", "validate"]) and None), [p], _user(p)
    return make


def _counts_case(k, rng):
    n = str(2 ** int(rng.integers(21, 80)))
    args = [["simulate", "arc-welder", "--contacts", n], ["simulate", "arc-welder", "--dwell-s", "1e308"],
            ["simulate", "delta-tracker", "--points", n], ["simulate", "scorbot-scanner", "--poses", n],
            ["plan", "arc-welder", "--candidates", n], ["simulate", "fleet", "--robots", n]][k % 6]

    def make(d):
        from typer.testing import CliRunner

        from pipeline.cli import app, load_commands

        def act():
            load_commands(args)
            r = CliRunner().invoke(app, [*args, "--out", str(d / "out")])
            if r.exception is not None and not isinstance(r.exception, SystemExit):
                raise r.exception
            return None
        return act, [], {}
    return make


def _figures_case(k, rng):
    base = float(rng.uniform(1e-6, 1e-2))
    v = [np.full(3, base), base + np.array([0, 1, 0]) * np.spacing(base), np.array([-1e300, 1e300, base]),
         np.array([np.nan, base, np.inf])][k % 4]

    def make(d):
        from pipeline.report.accuracy import histograms
        from pipeline.report.plots import point_sigma

        def act():
            with np.errstate(all="ignore"):
                point_sigma(np.arange(v.size), v)
                histograms(v, v, base)
        return act, [], {}
    return make


MAKERS = {"csv": _csv_case, "urdf": _urdf_case, "ros2bag": _bag_case, "campaign": _campaign_case,
          "targets": _targets_case, "runfolder": _runfolder_case, "archive": _archive_case,
          "recording": _recording_case, "counts": _counts_case, "figures": _figures_case,
          "options": lambda k, rng: fuzz_door.options_case(k, _base()),
          "outputs": lambda k, rng: fuzz_door.outputs_case(k, _base())}
PERIOD = {"csv": 12, "urdf": 11, "ros2bag": 5, "campaign": 7, "targets": 9, "runfolder": 7, "archive": 5,
          "recording": 4, "counts": 6, "figures": 4, "options": len(fuzz_door.OPTIONS),
          "outputs": len(fuzz_door.OUTPUTS)}  # cases per class that cover every kind of edit once
REFUSE = {"options": lambda k: True, "outputs": lambda k: True, "targets": lambda k: k % 9 >= 6}


def surface_cases(seed: int, per_class: int | None = None, classes: tuple[str, ...] = SURFACES) -> Iterator[SurfaceCase]:
    """`per_class` cases of every surface (default: one of each kind of edit), reproducible from `seed`."""
    for cls in classes:
        for k in range(per_class or PERIOD[cls]):
            rng = np.random.default_rng([seed, SURFACES.index(cls), k])
            yield SurfaceCase(cls, f"{cls}-{k}", MAKERS[cls](k, rng), REFUSE.get(cls, lambda k: False)(k))
