"""Where robocal may write a file the user named: a new path, an empty file, or a file robocal wrote.

robocal never overwrites a file it did not create: an existing non-empty file is replaced only
when robocal's own mark is at its start —
* a recording: an MCAP whose header names robocal as the writing library (every robocal writer
  sets `library` to "robocal/<version>…");
* a JSON document (plan / campaign files, acquire --summary, device-sim --report, simulate
  --truth): its first key is `"generator": "robocal/<version>"`
  (or `"kind": "robocal.…"`, the campaign files written before the generator key);
* an HTML page (report, fleet page): `<meta name="generator" content="robocal/…">` in its head;
* a CSV (compensated programs): robocal's program header (`"row","name","status",` … ending in
  `"predicted_sigma_m","correction_m","sigma_min_m","model_error_m"`).
Anything else is a one-line error naming the file.

A recording is data, not a cache, and so is the truth file a simulation writes beside it: robocal
replaces one of its own only with `--force`, which first keeps it as ``NAME.bak`` (an existing
``.bak`` is never overwritten: that is a one-line error).  A recording of real measurements — one
`robocal acquire` wrote (its header says so, or its `robocal.acquisition` metadata), or one cut short
(no footer: a crashed acquisition, `robocal recover` it) — is never replaced, even with `--force`.
Documents derived from recordings (plans, programs, reports, fleet pages, summaries) are replaced
when robocal wrote them."""

from __future__ import annotations

import os
import re
import struct
from pathlib import Path

from pipeline import __version__
from pipeline.errors import RobocalError
from pipeline.recording.framing import MAGIC

ACQUIRED = "acquire"  # the word in an MCAP header's library that marks a recording of real measurements
GENERATOR = f"robocal/{__version__}"  # the first key of every JSON document robocal writes for the user
PROGRAM_HEADER_START = b'"row","name","status",'
PROGRAM_HEADER_END = b'"predicted_sigma_m","correction_m","sigma_min_m","model_error_m"'
_JSON_MARK = re.compile(rb'^\s*\{\s*"(?:generator|kind)"\s*:\s*"robocal[./]')
_HTML_MARK = re.compile(rb'^\s*<!DOCTYPE html>[^\0]{0,600}?<meta name="generator" content="robocal/', re.I)


def _mcap_library(head: bytes) -> str:
    """The `library` of an MCAP file's header record ("" when `head` does not start with one)."""
    if not head.startswith(MAGIC) or len(head) < 17 or head[8] != 0x01:
        return ""
    try:
        o = 17 + 4 + struct.unpack_from("<I", head, 17)[0]  # magic 8 + opcode 1 + record length 8, then profile
        (n,) = struct.unpack_from("<I", head, o)
        return head[o + 4:o + 4 + n].decode("utf-8")
    except (struct.error, UnicodeDecodeError):
        return ""


def _mcap_by_robocal(head: bytes) -> bool:
    return _mcap_library(head).startswith("robocal")


def library_of(path: str | Path) -> str:
    """The library named in the MCAP header of `path` ("" for anything else): "robocal/<version>[ origin]"."""
    try:
        with open(path, "rb") as f:
            return _mcap_library(f.read(4096))
    except OSError:
        return ""


def measured(path: Path) -> str:
    """Why the robocal recording `path` holds real measurements robocal must never replace ("" if it does
    not): `robocal acquire` wrote it (or recovered / upgraded one: the header's library names
    ``acquire``, or a `robocal.acquisition` metadata record is in its last 1 MiB), or it has no footer
    (cut short: an acquisition that crashed, to `robocal recover`)."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(4096)
        f.seek(max(0, size - (1 << 20)))
        tail = f.read()
    if ACQUIRED in _mcap_library(head).split() or b"robocal.acquisition" in tail:
        return "is a recording of real measurements (robocal acquire)"
    if not tail.endswith(MAGIC):
        return "is a recording cut short (no footer: a crashed acquisition? `robocal recover` it)"
    return ""


def _csv_by_robocal(head: bytes) -> bool:
    first = head.split(b"\n", 1)[0].rstrip(b"\r")
    return first.startswith(PROGRAM_HEADER_START) and first.endswith(PROGRAM_HEADER_END)


def written_by_robocal(path: Path) -> bool:
    """True when `path` starts with robocal's mark: an MCAP header whose library is robocal's, a
    JSON document whose first key is robocal's generator, an HTML page with robocal's generator meta
    tag, or robocal's program CSV header."""
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except OSError:
        return False
    return (_mcap_by_robocal(head) or bool(_JSON_MARK.match(head)) or bool(_HTML_MARK.match(head))
            or _csv_by_robocal(head))


def generated(doc: dict) -> dict:
    """`doc` with robocal's generator as its first key: the mark that lets robocal replace the file later."""
    return {"generator": GENERATOR, **{k: v for k, v in doc.items() if k != "generator"}}


def distinct_outputs(**paths: str | Path | None) -> None:
    """RobocalError when two of a command's output paths (by option name) are the same file: one
    would silently replace the other (e.g. `--out x.mcap --truth x.mcap`)."""
    seen: dict[Path, str] = {}
    for name, p in paths.items():
        if p is None:
            continue
        key = Path(p).resolve()
        if key in seen:
            raise RobocalError(f"{p}: given as both --{seen[key]} and --{name}; they must be different files")
        seen[key] = name


DATA = ("recording", "truth")  # what robocal replaces only with --force, keeping a .bak


def backup_path(path: str | Path) -> Path:
    """Where --force keeps the file it replaces: ``NAME.bak`` beside it."""
    p = Path(path)
    return p.with_name(p.name + ".bak")


def check_output(path: str | Path, what: str = "recording", force: bool | None = False) -> Path:
    """`path` if robocal may write its `what` there, else RobocalError (see module docstring).
    `force`: the command's --force (None: the command has none, e.g. `robocal acquire`)."""
    p = Path(path)
    if p.is_dir():
        raise RobocalError(f"{p}: is a folder; give the {what}'s file name")
    if not (p.exists() and p.stat().st_size > 0):
        return p
    if not written_by_robocal(p):
        raise RobocalError(f"{p}: exists and was not written by robocal; robocal never overwrites a file it did "
                           "not create (choose another output path)")
    if what not in DATA:
        return p
    why = measured(p) if what == "recording" else ""
    if why:
        raise RobocalError(f"{p}: {why}; robocal never replaces it, even with --force (choose another output path)")
    bak = backup_path(p)
    if not force:
        how = "" if force is None else f", or --force to keep the old one as {bak.name}"
        raise RobocalError(f"{p}: holds a {what} already; robocal never replaces one silently (choose another "
                           f"output path{how})")
    if bak.exists():
        raise RobocalError(f"{p}: --force would keep the old {what} as {bak}, which exists already; robocal never "
                           "overwrites a backup (move it away first)")
    return p


def claim_output(path: str | Path, what: str = "recording", force: bool | None = False) -> Path:
    """`check_output`, then with --force the existing `what` moved to ``NAME.bak`` (kept, never
    overwritten) before anything is written: call it once everything else was checked."""
    p = check_output(path, what, force)
    if force and what in DATA and p.exists() and p.stat().st_size > 0:
        bak = backup_path(p)
        try:
            os.link(p, bak)  # fails if a .bak appeared meanwhile: nothing is overwritten
        except FileExistsError:
            raise RobocalError(f"{p}: --force would keep the old {what} as {bak}, which exists already") from None
        except OSError:  # a file system without hard links
            if bak.exists():
                raise RobocalError(f"{p}: --force would keep the old {what} as {bak}, which exists already") from None
            os.rename(p, bak)
            return p
        p.unlink()
    return p


def check_outputs(force: bool | None, **paths: str | Path | None) -> list[tuple[Path, str]]:
    """A command's output files by option name (``out``: the recording; any other name: that document,
    e.g. ``truth``): distinct and each allowed (`check_output`).  Call before any work."""
    distinct_outputs(**paths)
    named = [(Path(p), "recording" if k == "out" else k) for k, p in paths.items() if p is not None]
    for p, what in named:
        check_output(p, what, force)
    return named


def claim_outputs(force: bool | None, **paths: str | Path | None) -> None:
    """`check_outputs` (all of them before any is touched), then with --force each file replaced kept as
    NAME.bak (`claim_output`).  Call once the input is checked, before writing."""
    for p, what in check_outputs(force, **paths):
        claim_output(p, what, force)


BAG_MARK = "robocal.writer"  # the key of a bag's metadata.yaml custom_data that says robocal wrote it


def bag_by_robocal(path: Path) -> bool:
    """A bag folder whose metadata.yaml carries robocal's mark (custom_data ``robocal.writer``)."""
    try:
        text = (Path(path) / "metadata.yaml").read_text(errors="replace")
    except OSError:
        return False
    return f"{BAG_MARK}: robocal/" in text or f"{BAG_MARK}: 'robocal/" in text


def check_bag_output(path: str | Path, force: bool = False) -> Path:
    """`path` if robocal may write a ROS 2 bag folder there: a new path or an empty folder; a bag robocal
    wrote only with `force` (kept as NAME.bak, never over an existing .bak); anything else refused."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise RobocalError(f"{p}: exists and is not a folder; a ROS 2 bag is a folder (choose another output path)")
    if not p.exists() or not any(p.iterdir()):
        return p
    if not bag_by_robocal(p):
        raise RobocalError(f"{p}: exists and was not written by robocal; robocal never overwrites a file it did "
                           "not create (choose another output path)")
    bak = backup_path(p)
    if not force:
        raise RobocalError(f"{p}: holds a bag already; robocal never replaces one silently (choose another output "
                           f"path, or --force to keep the old one as {bak.name})")
    if bak.exists():
        raise RobocalError(f"{p}: --force would keep the old bag as {bak}, which exists already; robocal never "
                           "overwrites a backup (move it away first)")
    return p


def claim_bag_output(path: str | Path, force: bool = False) -> Path:
    """`check_bag_output`, then the folder made free for a new bag: an empty folder removed (rosbags writes
    a new one), a bag robocal wrote moved to NAME.bak with `force`."""
    p = check_bag_output(path, force)
    if p.is_dir() and not any(p.iterdir()):
        p.rmdir()
    elif p.exists():
        os.rename(p, backup_path(p))  # checked free above; rename never replaces a folder that appeared
    return p
