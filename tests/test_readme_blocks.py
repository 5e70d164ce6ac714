"""Every ```sh block of README.md runs as the README shows it, in order, in one scratch folder laid out like the
repository (its `.venv`, `recordings/` and `schemas/` linked, and `../shared/real-data` beside it when the real
datasets are present). A block fails the test on a non-zero exit.

Set-up blocks — every line a `make <target>` — are not re-run (they are what runs this suite); their targets
are checked to exist in the Makefile (`make -n`). A block that reads `../shared/real-data` skips, saying so,
where the real datasets are absent. Links in README.md to files of the repository are checked to exist too.
"""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
REAL = REPO.parent / "shared" / "real-data"
if not REAL.is_dir():
    REAL = Path("/work/shared/real-data")


def sh_blocks(text: str) -> list[str]:
    """The bodies of the ```sh fenced blocks, in order."""
    return re.findall(r"^```sh\n(.*?)^```", text, flags=re.S | re.M)


def command_lines(block: str) -> list[str]:
    """The block's commands: comments stripped, continuation lines joined."""
    joined = block.replace("\\\n", " ")
    lines = [re.sub(r"\s+#.*$", "", line).strip() for line in joined.splitlines()]
    return [line for line in lines if line and not line.startswith("#")]


def is_setup(block: str) -> bool:
    return all(re.fullmatch(r"make [\w-]+", line) for line in command_lines(block))


BLOCKS = sh_blocks(README.read_text())


def test_readme_has_the_setup_block_first():
    assert BLOCKS, "README.md has no ```sh block"
    assert is_setup(BLOCKS[0]) and command_lines(BLOCKS[0]) == ["make demo", "make test"]


def test_setup_targets_exist():
    targets = [line.split()[1] for b in BLOCKS if is_setup(b) for line in command_lines(b)]
    r = subprocess.run(["make", "-n", "-f", str(REPO / "Makefile"), *targets], cwd=REPO, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0, r.stderr


def test_readme_links_resolve():
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", README.read_text()):
        if not target.startswith(("http:", "https:")):
            assert (REPO / target).exists(), f"README.md links to {target}, which does not exist"


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    """A folder laid out like the repository's root, with ../shared/real-data beside it when available."""
    root = tmp_path_factory.mktemp("readme")
    repo = root / "repo"
    repo.mkdir()
    for name in (".venv", "recordings", "schemas", "Makefile"):
        (repo / name).symlink_to(REPO / name)
    if REAL.is_dir():
        (root / "shared").mkdir()
        (root / "shared" / "real-data").symlink_to(REAL)
    return repo


@pytest.mark.parametrize("index", [i for i, b in enumerate(BLOCKS) if not is_setup(b)])
def test_readme_block_runs(scratch, index):
    block = BLOCKS[index]
    if "../shared/real-data" in block and not (scratch.parent / "shared" / "real-data").is_dir():
        pytest.skip("../shared/real-data is absent (real datasets not shipped): the README's quick start needs it")
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV",)}
    env["PATH"] = os.pathsep.join([str(REPO / ".venv" / "bin"), env.get("PATH", "")])
    r = subprocess.run(["bash", "-e", "-o", "pipefail", "-c", block], cwd=scratch, env=env, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, f"README block {index} failed (exit {r.returncode}):\n{block}\n--- stdout\n" \
                              f"{r.stdout[-3000:]}\n--- stderr\n{r.stderr[-3000:]}"
