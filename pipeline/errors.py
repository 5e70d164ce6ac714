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


MAX_COUNT = 100_000  # points, poses, candidates a command line may ask to simulate or plan
MAX_CONTACTS = 5_000  # touch contacts of one simulated campaign (~2 400 encoder samples each: ~0.3 GB of recording)


def at_most(option: str, value: int | None, limit: int = MAX_COUNT) -> None:
    """One line when a count given on the command line is beyond what robocal simulates or plans."""
    if value is not None and value > limit:
        raise RobocalError(f"{option} {value}: more than robocal simulates or plans in one go ({limit:,})")
