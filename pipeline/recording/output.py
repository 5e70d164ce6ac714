"""Where robocal may write a recording: a new path, an empty file, or a recording robocal wrote.

robocal never overwrites a file it did not create: an existing non-empty file is replaced only
when it is an MCAP whose header names robocal as the writing library (every robocal writer sets
`library` to "robocal/<version>…").  Anything else is a one-line error."""

from __future__ import annotations

import struct
from pathlib import Path

from pipeline.errors import RobocalError
from pipeline.recording.framing import MAGIC


def written_by_robocal(path: Path) -> bool:
    """True when `path` starts with an MCAP header record whose library is robocal's."""
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except OSError:
        return False
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


def check_output(path: str | Path) -> Path:
    """`path` if robocal may write a recording there, else RobocalError (see module docstring)."""
    p = Path(path)
    if p.is_dir():
        raise RobocalError(f"{p}: is a folder; give the recording's file name")
    if p.exists() and p.stat().st_size > 0 and not written_by_robocal(p):
        raise RobocalError(f"{p}: exists and was not written by robocal; robocal never overwrites a file it did "
                           "not create (choose another output path)")
    return p
