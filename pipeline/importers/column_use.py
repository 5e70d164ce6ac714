"""Which quantity each column of a measurement table feeds (`robocal import csv`): one column, one quantity.

A joint's reading comes from the column named after the joint (and its direction of approach from
``dir_<joint>``); the options map the other columns — the positions (``--position-cols``, each
``--target-cols``, each ``--tip LINK=X,Y,Z``), the orientation (``--orientation-cols``) and a plane's
offset (``--plane NAME:N:OFFSET``).  A column named twice — twice in one option, in two options, or a
joint's column given as a position — would feed two quantities the same numbers: one marker
calibrated as two tips, a position whose x and y are equal.  That is refused before the table is
read, in one line naming the option and the column.  Checked here too: how many columns each
option takes.
"""

from __future__ import annotations

from pipeline.errors import RobocalError

AXES = {"position": ("x", "y", "z"), "rpy": ("roll", "pitch", "yaw"), "quat": ("qx", "qy", "qz", "qw"),
        "offset": ("offset",)}


def check_column_use(groups: list[tuple[str, str, tuple[str, ...]]], joints: list[str]) -> None:
    """`groups`: (option as the user typed it, kind — a key of `AXES` —, its columns) in the order given;
    `joints`: the joints read from their own columns.  RobocalError (one line) when an option has the
    wrong number of columns or a column feeds two quantities."""
    owner: dict[str, str] = {j: f"the reading of joint {j!r}" for j in joints}
    owner |= {f"dir_{j}": f"the direction of approach of joint {j!r}" for j in joints}
    for label, kind, cols in groups:
        axes = AXES[kind]
        if len(cols) != len(axes) or not all(cols):
            raise RobocalError(f"{label}: expected {len(axes)} column name(s) ({','.join(axes)}), got {len(cols)}")
        mine: dict[str, str] = {}
        for axis, c in zip(axes, cols):
            if c in mine:
                raise RobocalError(f"{label}: column {c!r} is given twice (as {mine[c]} and as {axis}); a column "
                                   "feeds one quantity only")
            if c in owner:
                raise RobocalError(f"{label}: column {c!r} is already {owner[c]}; a column feeds one quantity only")
            mine[c] = axis
        owner |= {c: f"the {axis} of {label}" for c, axis in mine.items()}
