"""Every shell block of README.md and docs/**/*.md runs as the page shows it (the convention: tests/doc_pages.py).

This file checks the pages against the convention (no shell block escapes the runner, every template has a runnable
twin, no absolute data paths) and runs the blocks of the pages that tests/doc_runner.py's `GROUPS` gives no other
file (one test per block, in page order, one scratch folder per page; what the runs must reach: doc_expect.py).
"""

from __future__ import annotations

import subprocess

from doc_pages import ABSOLUTE, REPO, SHELL_LANGS, blocks, indented_commands, is_setup, shown_commands, twins_missing
from doc_runner import GROUPS, PAGES, PENDING, RUNNABLE, block_test, scratch  # noqa: F401 (the runner's fixture)

CHECKED = {page: bs for page, bs in PAGES.items() if page not in PENDING}


def test_every_page_is_read():
    assert "README.md" in PAGES and any(p.startswith("docs/guide/") for p in PAGES)
    assert RUNNABLE, "no ```sh block found"
    assert set(PENDING) <= set(PAGES), "a pending page that no longer exists: remove it from PENDING"
    named = [p for ps in GROUPS.values() for p in ps]
    assert set(named) <= set(PAGES) and len(named) == len(set(named)), "GROUPS names a page twice or a lost page"
    assert all((REPO / "tests" / f).is_file() for f in GROUPS), "a file of GROUPS is missing"


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


# ----- running the blocks of the pages no other file runs -----------------------------------------------------

test_block_runs_as_printed = block_test(__file__)
