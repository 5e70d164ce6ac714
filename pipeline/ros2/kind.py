"""Is this input a ROS 2 bag?  Cheap checks on the first bytes, no bag library needed.

A ROS 2 bag is a folder with ``metadata.yaml`` (what ``ros2 bag record`` writes; or, from a
recorder killed before writing it, with ``ros2``-profile MCAP files), or one of its
storage files on its own: an SQLite3 database (``.db3``) or an MCAP file whose header profile is
``ros2`` (robocal's own recordings carry profile ``robocal``) or, under another profile, whose
summary lists CDR-encoded channels (rosbags then says which profile it cannot read).
"""

from __future__ import annotations

import struct
from pathlib import Path

MCAP_MAGIC = b"\x89MCAP0\r\n"
SQLITE_MAGIC = b"SQLite format 3\x00"


def mcap_profile(path: Path) -> str | None:
    """The profile string of an MCAP file's header record, or None when `path` is not MCAP."""
    try:
        with open(path, "rb") as f:
            head = f.read(8 + 1 + 8 + 4 + 256)
    except OSError:
        return None
    if head[:8] != MCAP_MAGIC or len(head) < 21 or head[8] != 0x01:
        return None
    (n,) = struct.unpack_from("<I", head, 17)
    if 21 + n > len(head):
        return None
    return head[21:21 + n].decode("utf-8", "replace")


def _cdr_channels(path: Path) -> bool:
    """The MCAP summary lists a channel with message encoding 'cdr' (False when it cannot be read)."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except Exception:  # noqa: BLE001 — a damaged file is not recognised here; its reader says what is wrong
        return False
    return summary is not None and any(c.message_encoding == "cdr" for c in summary.channels.values())


def ros2_kind(path: str | Path) -> str | None:
    """'folder', 'mcap' or 'sqlite3' when `path` is a ROS 2 bag (or its storage file), else None."""
    p = Path(path)
    if p.is_dir():
        if (p / "metadata.yaml").is_file() or any(mcap_profile(f) == "ros2" for f in sorted(p.glob("*.mcap"))[:4]):
            return "folder"
        return None
    if not p.is_file():
        return None
    profile = mcap_profile(p)
    if profile == "ros2" or (profile not in (None, "robocal") and _cdr_channels(p)):
        return "mcap"
    try:
        with open(p, "rb") as f:
            head = f.read(len(SQLITE_MAGIC))
    except OSError:
        return None
    return "sqlite3" if head == SQLITE_MAGIC else None


def not_a_recording_hint(path: str | Path) -> str | None:
    """What to do when a ROS 2 bag is given where a robocal recording is expected, or None."""
    if ros2_kind(path) is None:
        return None
    return (f"{path}: is a ROS 2 bag, not a robocal recording: give the robot and the topics, "
            "`robocal run BAG --urdf ROBOT.urdf --root LINK --tip LINK --measure-topic TOPIC --out DIR` "
            "(or `robocal import ros2 BAG ... --out REC.mcap` first; docs/guide/import-ros2.md)")
