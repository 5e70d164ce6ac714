"""The runner of the documentation's ```sh blocks (the convention: tests/doc_pages.py; the checks: doc_expect.py).

One test per ```sh block, in page order, in one scratch folder per page (a block runs the page's earlier blocks
first when they have not run in this process, so any selection of the tests keeps the page's order). A block
fails on a non-zero exit; after a page's last block, `doc_expect.EXPECT` checks what the page's commands made.

The pages are shared out among a few test files (`GROUPS`; every page not named there runs in
tests/test_doc_blocks.py) so that the suite's two xdist workers, which take one test file at a time, can share
them. Each file is one line: ``test_block_runs_as_printed = block_test(__file__)``.

Set `DOC_BLOCK_TIMES=FILE` to append one line per block (page, line, wall s, CPU s of its processes).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from doc_expect import EXPECT
from doc_pages import REPO, Outcome, blocks, is_setup, needs_real_data, pages, run_block, scratch_root

DEFAULT = "test_doc_blocks.py"
# test file → the pages whose blocks it runs (the heaviest pages apart: their CPU is in tests/ci_costs.json)
GROUPS: dict[str, tuple[str, ...]] = {
    "test_doc_blocks_import.py": ("docs/guide/import-csv.md", "docs/guide/import-ros2.md",
                                  "docs/reference/ros-outputs.md"),
    "test_doc_blocks_real.py": ("README.md", "docs/guide/camera.md", "docs/guide/dynamics.md", "docs/guide/view.md"),
    "test_doc_blocks_sim.py": ("docs/guide/acquire.md", "docs/guide/diagnose.md", "docs/guide/fleet.md",
                               "docs/guide/physics.md", "docs/guide/plan.md"),
}
# Pages whose blocks another change is converting right now: skipped, saying so, and left out of the page checks
# until it lands (an entry here is a debt: remove it with the change that makes the page run).
PENDING: dict[str, str] = {}

# Pages whose every block a test file of their own runs as printed, with the page's checks (when that file exists,
# the runner leaves the page to it: one run of a page's commands in the suite).
ELSEWHERE: dict[str, str] = {"docs/guide/dynamics.md": "tests/test_dynamics_guide.py"}

# Pages whose blocks are marked `extended` (`make test-extended` runs them; CI's `make test` leaves them out of
# its 20-minute budget): the costliest pages, each with the capability's own tests in CI.
EXTENDED: dict[str, str] = {
    "docs/guide/import-csv.md": "tests/test_urdf_import.py, tests/test_accuracy_real_sessions.py (TIAGo's frozen protocol)",
    "docs/guide/import-ros2.md": "tests/test_ros2_import.py, tests/test_ros2_robot_from_bag.py",
    "docs/guide/plan.md": "tests/test_plan_select.py, tests/test_plan_staged.py, tests/test_plan_approach.py",
    "docs/guide/physics.md": "tests/test_physics_whole.py, tests/test_physics_run.py",
    "docs/guide/diagnose.md": "tests/test_diagnose_arc_welder.py, tests/test_diagnose_independent.py",
    "docs/guide/acquire.md": "tests/test_acquire_pty.py, tests/test_acquire_crash.py",
    "docs/guide/fleet.md": "tests/test_reprocess_archive.py",
    "docs/guide/calibrate.md": "tests/test_pipeline_run.py, tests/test_urdf_import.py",
    "docs/reference/systems/delta.md": "tests/test_delta_calibration.py",
    "docs/guide/accuracy.md": "tests/test_accuracy_holdout.py, tests/test_accuracy_information.py",
    "docs/guide/view.md": "tests/test_rerun_robot.py, tests/test_view_raw.py",
}  # page → the tests that cover its capability in CI

PAGES = {p.relative_to(REPO).as_posix(): blocks(p) for p in pages()}
RUNNABLE = [b for bs in PAGES.values() for b in bs if b.lang == "sh" and not is_setup(b)]


def group_of(page: str) -> str:
    return next((f for f, ps in GROUPS.items() if page in ps), DEFAULT)


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


def run_as_printed(scratch: Path, block) -> None:
    """Run `block` (after its page's earlier blocks) and, after the page's last block, the page's checks."""
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
    if block is page[-1] and block.page in EXPECT:
        EXPECT[block.page](scratch_root(scratch, block.page))


def block_test(test_file: str):
    """The parametrized test of the blocks of the pages `test_file` (a test module's __file__) runs."""
    name = Path(test_file).name
    mine = [b for b in RUNNABLE if group_of(b.page) == name
            and not (b.page in ELSEWHERE and (REPO / ELSEWHERE[b.page]).is_file())]

    def marks(b):
        return (pytest.mark.extended,) if b.page in EXTENDED else ()

    @pytest.mark.parametrize("block", [pytest.param(b, id=b.name, marks=marks(b)) for b in mine])
    def test_block_runs_as_printed(scratch, block):
        run_as_printed(scratch, block)

    return test_block_runs_as_printed
