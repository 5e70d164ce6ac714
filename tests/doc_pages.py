"""The documentation's shell blocks, read as a user reads them, and run as printed (tests/doc_runner.py).

Convention of every page (README.md and docs/**/*.md):

- A ```sh block runs as printed, in page order, in one scratch folder per page laid out like the repository's
  root (`.venv`, `recordings/`, `schemas/`, `benchmarks/`, `tests/`, `docs/` and the Makefile linked; the real
  datasets at `../shared/real-data` beside it when they are present). Blocks that make files for later blocks of
  the page run first. A block that names `../shared/real-data` — and every later block of its page — is skipped,
  saying so, where the real datasets are absent.
- A ```sh block whose every line is `make <target>` is a set-up block: it is what runs this suite, so its
  targets are only checked to exist (`make -n`), not run again.
- A block that shows a command's form with placeholders (`REC.mcap`, `[--option …]`, `a|b`) is a ```text block
  preceded by the line `<!-- doc-test: template -->`; a block of full-size benchmark commands (minutes or hours)
  is a ```text block preceded by `<!-- doc-test: benchmark -->`. Neither runs, and every command in it must have
  a runnable twin on the same page: a ```sh block with the same `robocal` subcommand, or the same benchmark
  script with a bounded size.
- No other block shows a command: ```bash, ```console, ```shell and the like are refused, and a ```text or
  unlabelled block holding a command line (`robocal …`, `python …`, `.venv/bin/…`, `make …`) fails the test.
- Real data is named by its path relative to the repository, `../shared/real-data/…`; an absolute path to it
  (or to this machine's `/work/…`) fails the test.
"""

from __future__ import annotations

import os
import re
import resource
import shlex
import signal
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path
from real_data import real_data

REPO = Path(__file__).resolve().parents[1]
REAL = real_data()  # ../shared/real-data (tests/real_data.py)

LINKED = (".venv", "recordings", "schemas", "benchmarks", "tests", "docs", "Makefile", "pyproject.toml")
SHELL_LANGS = {"bash", "console", "shell", "zsh", "shell-session", "shellsession", "sh-session", "fish", "ksh"}
COMMAND = re.compile(r"^(?:\$\s+)?(robocal|\.venv/bin/\S+|python3?|make|source|pip)(?:\s|$)")
MARKER = re.compile(r"^<!--\s*doc-test:\s*(template|benchmark)\s*-->\s*$")
ABSOLUTE = re.compile(r"(?<![\w.~])/(?:work|home|tmp/\S*shared)/\S*|(?<![\w.])/\S*shared/real-data")


@dataclass(frozen=True)
class Block:
    page: str        # path relative to the repository
    line: int        # line of the opening fence (1-based)
    lang: str        # the fence's info string ('' when unlabelled)
    body: str
    marker: str      # 'template', 'benchmark' or ''

    @property
    def name(self) -> str:
        return f"{self.page}:{self.line}"


def pages() -> list[Path]:
    return [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]


def blocks(page: Path) -> list[Block]:
    """Every fenced block of `page`, in order, with the marker line directly above it (if any)."""
    rel = page.relative_to(REPO).as_posix() if page.is_relative_to(REPO) else page.name
    lines = page.read_text().split("\n")
    out, i = [], 0
    while i < len(lines):
        m = re.match(r"^(\s*)(`{3,}|~{3,})\s*([^\s`]*)", lines[i])
        if not m:
            i += 1
            continue
        indent, fence, lang = m.group(1), m.group(2), m.group(3)
        start, body = i, []
        i += 1
        while i < len(lines) and not re.match(rf"^\s*{re.escape(fence)}\s*$", lines[i]):
            body.append(lines[i][len(indent):] if lines[i].startswith(indent) else lines[i])
            i += 1
        above = next((lines[j] for j in range(start - 1, -1, -1) if lines[j].strip()), "")
        mk = MARKER.match(above.strip())
        out.append(Block(rel, start + 1, lang.lower(), "\n".join(body) + "\n", mk.group(1) if mk else ""))
        i += 1
    return out


def indented_commands(page: Path) -> list[tuple[int, str]]:
    """(line, text) of commands shown in an indented (4-space) code block, outside the fences: they escape the runner."""
    out, fence = [], None
    for i, line in enumerate(page.read_text().split("\n"), 1):
        m = re.match(r"^\s*(`{3,}|~{3,})", line)
        if m and (fence is None or m.group(1).startswith(fence)):
            fence = None if fence else m.group(1)
        elif fence is None and re.match(r"^(?: {4}|\t)\s*(?:\$\s+)?(?:robocal|python3?|\.venv/bin/)\S*(?:\s|$)", line):
            out.append((i, line.strip()))
    return out


def command_lines(body: str) -> list[str]:
    """The block's commands: continuation lines joined, comments and blank lines dropped."""
    joined = body.replace("\\\n", " ")
    lines = [re.sub(r"(^|\s)#.*$", "", line).strip() for line in joined.splitlines()]
    return [line for line in lines if line]


def shown_commands(body: str) -> list[str]:
    """Lines of a block a reader would copy to a shell: `robocal …`, `python …`, `.venv/bin/…`, `make …`."""
    return [re.sub(r"^\$\s+", "", line) for line in command_lines(body) if COMMAND.match(line)]


def is_setup(block: Block) -> bool:
    lines = command_lines(block.body)
    return bool(lines) and all(re.fullmatch(r"make [\w-]+", line) for line in lines)


def command_key(line: str) -> tuple[str, ...]:
    """What a runnable twin must share with a template's command: `robocal` and its subcommand words (lower-case
    words before the first option, placeholder or path), or the interpreter and the script it runs."""
    line = re.sub(r"^\$\s+", "", line)
    try:
        words = shlex.split(line, comments=False)
    except ValueError:
        words = line.split()
    words = [re.sub(r"^\.venv/bin/", "", w) for w in words]
    if words and words[0] in ("python", "python3"):
        return tuple(words[:2])
    key = [words[0]] if words else []
    for w in words[1:3]:
        if not re.fullmatch(r"[a-z][a-z0-9-]*", w):
            break
        key.append(w)
    return tuple(key)


def twins_missing(page_blocks: list[Block]) -> list[str]:
    """Commands of the page's template / benchmark blocks that no ```sh block of the page runs."""
    ran = [command_key(c) for b in page_blocks if b.lang == "sh" for c in command_lines(b.body)]
    ran += [command_key(part) for b in page_blocks if b.lang == "sh" for c in command_lines(b.body)
            for part in re.split(r"\s*(?:&&|;|\|\|?)\s*|\bdo\s+", c) if part]
    missing = []
    for b in page_blocks:
        if b.marker:
            for c in shown_commands(b.body):
                key = command_key(c)
                if not any(k[:len(key)] == key for k in ran):
                    missing.append(f"{b.name}: `{' '.join(key)}` ({b.marker}) has no ```sh twin on the page")
    return missing


def needs_real_data(block: Block) -> bool:
    return "../shared/real-data" in block.body


def scratch_root(base: Path, page: str) -> Path:
    """A folder laid out like the repository's root for `page`, with ../shared/real-data beside it when present."""
    root = base / re.sub(r"[^\w]+", "_", page)
    repo = root / "repo"
    if not repo.is_dir():
        repo.mkdir(parents=True)
        for name in LINKED:
            if (REPO / name).exists():
                (repo / name).symlink_to(REPO / name)
        if REAL.is_dir():
            (root / "shared").mkdir()
            (root / "shared" / "real-data").symlink_to(REAL)
    return repo


@dataclass
class Outcome:
    returncode: int
    stdout: str
    stderr: str
    wall_s: float
    cpu_s: float


def group_cpu_s(pgid: int) -> float:
    """CPU seconds (user + system, with their reaped children) of the live processes of process group `pgid`."""
    total, tick = 0.0, os.sysconf("SC_CLK_TCK")
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if int(fields[2]) == pgid:  # fields after the name: state ppid pgrp … utime(11) stime(12) cutime cstime
            total += sum(int(v) for v in fields[11:15]) / tick
    return total


def run_block(block: Block, cwd: Path, timeout: float = 900) -> Outcome:
    """Run `block` with bash (-e, pipefail) in `cwd`, `.venv/bin` first on PATH; its output in files beside `cwd`
    (a block may leave a process in the background: the whole process group is ended when the block ends)."""
    env = {k: v for k, v in os.environ.items() if k != "VIRTUAL_ENV"}
    env["PATH"] = os.pathsep.join([str(REPO / ".venv" / "bin"), env.get("PATH", "")])
    logs = cwd.parent / "logs"
    logs.mkdir(exist_ok=True)
    out, err = logs / f"{block.line}.out", logs / f"{block.line}.err"
    before, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    with out.open("w") as fo, err.open("w") as fe:
        proc = subprocess.Popen(["bash", "-e", "-o", "pipefail", "-c", block.body], cwd=cwd, env=env, stdout=fo,
                                stderr=fe, stdin=subprocess.DEVNULL, start_new_session=True)
        try:
            code = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            code = -1
            fe.write(f"\n[doc test] block timed out after {timeout:.0f} s\n")
        finally:
            left = group_cpu_s(proc.pid)  # processes the block left running (a simulator in the background)
            try:
                os.killpg(proc.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
            proc.wait()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime) + left
    return Outcome(code, out.read_text(), err.read_text(), time.perf_counter() - t0, cpu)
