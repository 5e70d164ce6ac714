"""Every shell block of README.md and docs/**/*.md runs as the page shows it (the convention: tests/doc_pages.py).

One test per ```sh block, in page order, in one scratch folder per page (a block runs the page's earlier blocks
first when they have not run in this process, so any selection or split of the tests keeps the page's order).
A block fails on a non-zero exit. Where a page's blocks leave files a user would look at, `EXPECT` checks them
too (the figures a capability must reach on real data). The pages are also checked for shell blocks that escape
the runner, templates without a runnable twin, and absolute paths to the data.

Set `DOC_BLOCK_TIMES=FILE` to append one line per block (page, line, wall s, CPU s of its processes).
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
from pathlib import Path

import pytest
from doc_pages import REPO, SHELL_LANGS, Outcome, blocks, indented_commands, is_setup, needs_real_data, pages, \
    run_block, scratch_root, shown_commands, twins_missing, ABSOLUTE

# Pages whose blocks another change is converting right now: skipped, saying so, and left out of the page checks
# until it lands (an entry here is a debt: remove it with the change that makes the page run).
PENDING: dict[str, str] = {}
PAGES = {p.relative_to(REPO).as_posix(): blocks(p) for p in pages()}
CHECKED = {page: bs for page, bs in PAGES.items() if page not in PENDING}
RUNNABLE = [b for bs in PAGES.values() for b in bs if b.lang == "sh" and not is_setup(b)]

try:  # keep a page's blocks on one worker when the suite runs under pytest-xdist (--dist loadgroup)
    import xdist  # noqa: F401
    HAVE_XDIST = True
except ImportError:
    HAVE_XDIST = False


def _marks(page: str) -> list:
    return [pytest.mark.xdist_group(page)] if HAVE_XDIST else []


def test_every_page_is_read():
    assert "README.md" in PAGES and any(p.startswith("docs/guide/") for p in PAGES)
    assert RUNNABLE, "no ```sh block found"
    assert set(PENDING) <= set(PAGES), "a pending page that no longer exists: remove it from PENDING"


def test_readme_has_the_setup_block_first():
    first = next(b for b in PAGES["README.md"] if b.lang == "sh")
    assert is_setup(first) and shown_commands(first.body) == ["make demo", "make test"]


def test_setup_targets_exist():
    targets = sorted({line.split()[1] for bs in PAGES.values() for b in bs if b.lang == "sh" and is_setup(b)
                      for line in shown_commands(b.body)})
    r = subprocess.run(["make", "-n", "-f", str(REPO / "Makefile"), *targets], cwd=REPO, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0, r.stderr


def test_no_shell_block_escapes_the_runner():
    bad = []
    for bs in CHECKED.values():
        for b in bs:
            if b.lang in SHELL_LANGS:
                bad.append(f"{b.name}: ```{b.lang} block: write ```sh (run by this test) or mark a ```text template")
            elif b.lang != "sh" and not b.marker and shown_commands(b.body):
                bad.append(f"{b.name}: a ```{b.lang or '(unlabelled)'} block shows `{shown_commands(b.body)[0]}`: "
                           "make it ```sh, or mark it <!-- doc-test: template --> / <!-- doc-test: benchmark -->")
            elif b.marker and b.lang != "text":
                bad.append(f"{b.name}: a {b.marker} block must be ```text")
    for page in CHECKED:
        bad += [f"{page}:{i}: an indented code block shows `{text}`: make it a ```sh block"
                for i, text in indented_commands(REPO / page)]
    assert not bad, "\n".join(bad)


def test_every_template_has_a_runnable_twin():
    missing = [m for bs in CHECKED.values() for m in twins_missing(bs)]
    assert not missing, "\n".join(missing)


def test_no_absolute_data_paths():
    bad = [f"{p}:{i}: {m.group(0)}" for p in CHECKED for i, line in enumerate((REPO / p).read_text().splitlines(), 1)
           for m in ABSOLUTE.finditer(line)]
    assert not bad, "name data relative to the repository (../shared/real-data/…):\n" + "\n".join(bad)


def test_convention_detects_what_it_must(tmp_path):
    """The checks above can fail: a console block, an unmarked command, a template without a twin, a /work path,
    a command in an indented code block."""
    from doc_pages import Block, command_key
    page = tmp_path / "p.md"
    page.write_text("Run:\n\n    robocal run x.mcap --out r\n\n```sh\n    robocal run y.mcap --out r\n```\n")
    assert indented_commands(page) == [(3, "robocal run x.mcap --out r")]
    assert [b.lang for b in blocks(page)] == ["sh"]
    assert command_key(".venv/bin/robocal import csv M.csv --urdf R.urdf") == ("robocal", "import", "csv")
    assert command_key("robocal run REC.mcap --out runs/x") == ("robocal", "run")
    assert command_key("python benchmarks/bench_x.py --seeds 20") == ("python", "benchmarks/bench_x.py")
    t = Block("p.md", 1, "text", "robocal plan arc-welder --select N --out C.json\n", "template")
    s = Block("p.md", 5, "sh", "robocal plan arc-welder --select 30 --out c.json\n", "")
    assert twins_missing([t]) and not twins_missing([t, s])
    assert shown_commands("$ robocal run x.mcap\nprose robocal\n") == ["robocal run x.mcap"]
    assert ABSOLUTE.search("--poses /work/shared/real-data/x") and not ABSOLUTE.search("../shared/real-data/x")
    assert not ABSOLUTE.search("/joint_states /dev/pts/3 /tmp/…/bridge")


# ----- running the blocks ------------------------------------------------------------------------------------

_ran: dict[tuple[str, int], Outcome] = {}


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    return tmp_path_factory.mktemp("docs")


def _run(block, base: Path) -> Outcome:
    key = (block.page, block.line)
    if key not in _ran:
        _ran[key] = out = run_block(block, scratch_root(base, block.page))
        if os.environ.get("DOC_BLOCK_TIMES"):
            with open(os.environ["DOC_BLOCK_TIMES"], "a") as f:
                f.write(json.dumps({"page": block.page, "line": block.line, "exit": out.returncode,
                                    "wall_s": round(out.wall_s, 2), "cpu_s": round(out.cpu_s, 2)}) + "\n")
    return _ran[key]


def _failure(block, out: Outcome) -> str:
    return (f"{block.name}: the block exits {out.returncode}:\n{block.body}--- stdout (end)\n{out.stdout[-3000:]}\n"
            f"--- stderr (end)\n{out.stderr[-3000:]}")


@pytest.mark.parametrize("block", [pytest.param(b, id=b.name, marks=_marks(b.page)) for b in RUNNABLE])
def test_block_runs_as_printed(scratch, block):
    if block.page in PENDING:
        pytest.skip(f"{block.page}: {PENDING[block.page]}")
    page = [b for b in RUNNABLE if b.page == block.page]
    upto = page[:page.index(block) + 1]
    if any(needs_real_data(b) for b in upto) and not (scratch_root(scratch, block.page).parent / "shared").is_dir():
        pytest.skip(f"{block.page} names ../shared/real-data, which is absent (real datasets not shipped)")
    for earlier in upto[:-1]:
        out = _run(earlier, scratch)
        if out.returncode != 0:
            pytest.fail(f"an earlier block of the page failed, so this one cannot run as printed:\n"
                        f"{_failure(earlier, out)}")
    out = _run(block, scratch)
    assert out.returncode == 0, _failure(block, out)
    last = block is page[-1]
    if last and block.page in EXPECT:
        EXPECT[block.page](scratch_root(scratch, block.page))


# ----- what the pages' runs must reach (real data; checked after a page's last block) ---------------------------

def _json(path: Path) -> dict:
    return json.loads(path.read_text())


def _findings(diagnosis: Path) -> list[tuple[str, str]]:
    return [(f["effect"], f["location"]) for f in _json(diagnosis)["findings"]]


def _acquire(repo: Path):
    """The acquired drive-state recording diagnoses as its source: the true compliance, measured torque."""
    values = []
    for d in ("d_src", "d_acq"):
        (f,) = _json(repo / d / "diagnosis.json")["findings"]
        assert (f["effect"], f["location"], f["source"]) == ("joint_compliance", "shoulder_lift_joint", "measured torque")
        values.append(f["parameters"][0]["value"])
    assert abs(values[0] - 3e-6) < 3e-7 and abs(values[1] - values[0]) < 1e-4 * values[0], values
    assert (repo / "restored.mcap").stat().st_size > 0 and (repo / "runs/x/results.json").is_file()


def _compensate(repo: Path):
    rows = list(csv.DictReader((repo / "program.csv").open()))
    assert [r["status"] for r in rows] == ["ok"] * 3, rows
    assert max(float(r["correction_m"]) for r in rows) > 1e-3  # the calibrated robot needs its program corrected


def _diagnose(repo: Path):
    """Each example's injected effects found and named, nothing else."""
    assert _findings(repo / "DIR/diagnosis.json") == [("joint_compliance", "J2")]
    assert _findings(repo / "WARM/diagnosis.json") == [("thermal_drift", "temperature link2")]
    assert sorted(_findings(repo / "DELTA/diagnosis.json")) == [("backlash", "A2"), ("thermal_drift", "campaign")]


def _fleet(repo: Path):
    """Exactly the injected step flagged, on the robot and month it was injected; the cluster ran arc-01's three."""
    robots = _json(repo / "fleet.json")["robots"]
    steps = {r: [(s["param"], s["recording"]) for s in f["steps"]] for r, f in robots.items()}
    assert steps == {"arc-01": [], "arc-02": [("J3.theta_offset", "arc-02/2026-02/campaign.mcap")]}, steps
    assert len((repo / "out-cluster/summary.csv").read_text().splitlines()) == 1 + 3


def _published(stated_mm: float, measured_m: float, what: str) -> None:
    """A figure the README states (to 0.01 mm, or 0.001 mm below 1 mm), measured again by the page's commands."""
    digits = 3 if stated_mm < 1 else 2
    assert round(measured_m * 1e3, digits) == stated_mm, (
        f"{what}: the commands give {measured_m * 1e3:.4f} mm where README.md states {stated_mm} mm — "
        "update README.md, the guide and this check together")


def _import_csv(repo: Path):
    """The README's figures of the four real datasets, through the guide's commands (import → run → evaluate)."""
    recs = {r["path"]: r for r in _json(repo / "runs/tiago-eval/evaluation.json")["recordings"]}
    for s, mm in (("2021-11-26", 2.82), ("2021-11-30-1403", 2.60), ("2021-11-30-1504", 2.40)):
        _published(mm, recs[f"tiago_{s}.mcap"]["rms_3d_m"], f"FIGAROH's TIAGo protocol, the recording of {s}")
    (ur10,) = _json(repo / "runs/ur10-eval/evaluation.json")["recordings"]
    _published(3.62, ur10["rms_3d_m"], "UR10e, every 5th row held out")
    (mate,) = _json(repo / "runs/mate-eval/evaluation.json")["recordings"]
    _published(1.91, mate["rms_normal_m"], "MATE, every 5th row held out (along the normals)")
    panda = _json(repo / "runs/panda_2-eval/evaluation.json")["recordings"]
    assert len(panda) == 8
    _published(0.429, sum(r["mean_3d_m"] for r in panda) / 8, "MUKCa's panda_2 protocol, mean over 8 placements")
    assert (repo / "runs/tiago/identify/model.urdf").is_file() and (repo / "runs/tiago-two/results.json").is_file()


def _import_ros2(repo: Path):
    """Bags written by rosbags from the TIAGo sessions give the CSV import's held-out figure; every pose paired."""
    (ev,) = _json(repo / "runs/tiago-bag-eval/evaluation.json")["recordings"]
    _published(2.82, ev["rms_3d_m"], "the TIAGo recording of 2021-11-26, from a bag")
    assert _json(repo / "runs/tiago-bag/results.json")["summary"]["status"] in ("pass", "warn")
    r = subprocess.run([str(REPO / ".venv/bin/python"), "-c", "import sys; from pipeline.recording.reader import "
                        "read_recording; print(read_recording(sys.argv[1]).metadata['robocal.campaign']['ros2']['pairing']['n_paired'])",
                        str(repo / "ur10.mcap")], capture_output=True, text=True, timeout=120)
    assert r.stdout.strip() == "23", r.stderr


def _physics(repo: Path):
    """The humanoid's tree calibrated from its CSV (the bag imports the same 80 points), every program row solved."""
    summary = _json(repo / "runs/h/results.json")["summary"]
    assert summary["holdout_rms_3d_m"] < 1e-3 and summary["status"] != "fail", summary
    for program in ("program.csv", "program-up.csv"):
        rows = list(csv.DictReader((repo / program).open()))
        assert [r["status"] for r in rows] == ["ok"] * 5, (program, rows)


def _plan(repo: Path):
    """The two-stage campaign lands (the page: 98.3 % over 20 pools), calibrates, and its pty copy is complete."""
    ex = _json(repo / "T.json")["campaign_execution"]
    assert ex["planned"] == 50 and ex["land_rate"] >= 0.94, ex
    assert _json(repo / "RUN1/results.json")["summary"]["status"] != "fail"


def _accuracy(repo: Path):
    """The map at the user's three points, the bound the page states for the jig grid passed the 0.25 mm tolerance."""
    acc = _json(repo / "runs/x/accuracy/accuracy.json")
    assert len(acc["map"]["points_m"]) == 3 and acc["status"] == "pass", acc["status"]
    assert (repo / "runs/y/results.json").is_file()


EXPECT: dict = {
    "docs/guide/accuracy.md": _accuracy,
    "docs/guide/plan.md": _plan,
    "docs/guide/physics.md": _physics,
    "docs/guide/import-ros2.md": _import_ros2,
    "docs/guide/import-csv.md": _import_csv,
    "docs/guide/fleet.md": _fleet,
    "docs/guide/diagnose.md": _diagnose,
    "docs/guide/acquire.md": _acquire,
    "docs/guide/compensate.md": _compensate,
}
