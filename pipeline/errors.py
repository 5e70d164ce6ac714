"""The one exception type the command line turns into a one-line message and exit code."""

from __future__ import annotations


class RobocalError(Exception):
    """A problem with the user's input, stated in one line (file, channel, record, reason)."""


def where(path: object, channel: str | None = None, record: int | str | None = None) -> str:
    """'file: channel /x: record 12' — the prefix of every input error."""
    parts = [str(path)]
    if channel:
        parts.append(f"channel {channel}")
    if record is not None:
        parts.append(f"record {record}")
    return ": ".join(parts)
