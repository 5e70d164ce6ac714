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
Anything else is a one-line error naming the file."""

from __future__ import annotations

import re
import struct
from pathlib import Path

from pipeline import __version__
from pipeline.errors import RobocalError
from pipeline.recording.framing import MAGIC

GENERATOR = f"robocal/{__version__}"  # the first key of every JSON document robocal writes for the user
PROGRAM_HEADER_START = b'"row","name","status",'
PROGRAM_HEADER_END = b'"predicted_sigma_m","correction_m","sigma_min_m","model_error_m"'
_JSON_MARK = re.compile(rb'^\s*\{\s*"(?:generator|kind)"\s*:\s*"robocal[./]')
_HTML_MARK = re.compile(rb'^\s*<!DOCTYPE html>[^\0]{0,600}?<meta name="generator" content="robocal/', re.I)


def _mcap_by_robocal(head: bytes) -> bool:
    if not head.startswith(MAGIC) or len(head) < 17 or head[8] != 0x01:
        return False
    try:
        o = 17  # magic 8 + opcode 1 + record length 8
        (n,) = struct.unpack_from("<I", head, o)
        o += 4 + n  # profile
        (n,) = struct.unpack_from("<I", head, o)
        library = head[o + 4:o + 4 + n].decode("utf-8")
    except (struct.error, UnicodeDecodeError):
        return False
    return library.startswith("robocal")


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


def check_output(path: str | Path, what: str = "recording") -> Path:
    """`path` if robocal may write its `what` there, else RobocalError (see module docstring)."""
    p = Path(path)
    if p.is_dir():
        raise RobocalError(f"{p}: is a folder; give the {what}'s file name")
    if p.exists() and p.stat().st_size > 0 and not written_by_robocal(p):
        raise RobocalError(f"{p}: exists and was not written by robocal; robocal never overwrites a file it did "
                           "not create (choose another output path)")
    return p
