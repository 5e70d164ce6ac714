"""The readable messages of a damaged ROS 2 bag (MCAP storage): what `ros2 bag reindex` and
`robocal recover` do for a recording cut short — a recorder killed before it wrote the MCAP footer
and `metadata.yaml`, a copy cut off, a damaged chunk.

rosbags refuses such a bag whole (it needs the footer, summary and metadata.yaml).  Here each
storage file is framed by robocal's own MCAP reader (`pipeline.recording.reader`: every complete
chunk and message, damage skipped), topic types come from the MCAP channels' schemas, and the
messages lost are named per topic: counted against `metadata.yaml` when it is there, otherwise
said to be unknown.  A SQLite3 (.db3) bag is not salvaged: its error stays as it was.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from pipeline.errors import RobocalError


@dataclass
class Salvaged:
    """Messages read from a damaged bag: topic → type, topic → [(receive time ns, CDR bytes)] in
    time order, and one warning line per loss."""

    topics: dict[str, str]
    messages: dict[str, list[tuple[int, bytes]]]
    warnings: list[str] = field(default_factory=list)


def storage_files(path: Path) -> list[Path]:
    """The MCAP storage files of the bag `path` (a bag folder or one .mcap file)."""
    path = Path(path)
    if path.is_file():
        return [path] if path.suffix == ".mcap" else []
    return sorted(path.glob("*.mcap")) if path.is_dir() else []


def _expected_counts(path: Path) -> dict[str, int] | None:
    """topic → message count from the bag's metadata.yaml, or None when it is absent or unreadable."""
    meta = (path if path.is_dir() else path.parent) / "metadata.yaml"
    try:
        from ruamel.yaml import YAML

        doc = YAML(typ="safe").load(meta.read_text())
        info = doc["rosbag2_bagfile_information"]
        return {t["topic_metadata"]["name"]: int(t["message_count"]) for t in info["topics_with_message_count"]}
    except Exception:  # noqa: BLE001 — absent or damaged: the counts are then unknown
        return None


def salvage(path: Path, why: str, message: str, wanted: set[str] | None = None) -> Salvaged:
    """The readable messages (of `wanted` topics, or all) of the damaged MCAP bag `path`; `why` is
    rosbags' complaint, kept in the warning.  Raises RobocalError when nothing can be read, and
    `message` (rosbags' refusal, as it was) when the bag is not damaged (an unsupported profile…)."""
    from pipeline.recording.reader import read_recording

    files = storage_files(path)
    if not files:
        raise RobocalError(f"{path}: cannot read as a ROS 2 bag ({why}); no MCAP storage file to salvage")
    topics: dict[str, str] = {}
    messages: dict[str, list[tuple[int, bytes]]] = {}
    notes: list[str] = []
    damaged = Path(path).is_dir() and not (Path(path) / "metadata.yaml").is_file()
    for f in files:
        try:
            rec = read_recording(f, topics=wanted, foreign=True)
        except RobocalError as e:
            notes.append(f"{e}")
            damaged = True
            continue
        for t, (schema, _enc) in rec.schemas.items():
            topics.setdefault(t, schema or "(unknown type)")
        for t, bodies in rec.messages.raw.items():
            messages.setdefault(t, []).extend(zip(rec.log_times.get(t, []), map(bytes, bodies)))
        notes += [w for w in rec.warnings]
        damaged = damaged or bool(rec.warnings) or not rec.complete
        if not rec.complete:
            notes.append(f"{f}: ends before the MCAP footer (cut short or the recorder was killed)")
    if not damaged:
        raise RobocalError(message)
    if not any(messages.values()):
        raise RobocalError(f"{path}: cannot read as a ROS 2 bag ({why}); no message could be salvaged")
    for t in messages:
        messages[t].sort(key=lambda m: m[0])
    expected = _expected_counts(Path(path))
    warnings = [f"{path}: damaged ROS 2 bag ({why}); calibrating from the messages that could be read"]
    for t in sorted(messages if wanted is None else wanted):
        got = len(messages.get(t, []))
        if expected is not None and t in expected:
            if expected[t] > got:
                warnings.append(f"{path}: topic {t}: {expected[t] - got} of {expected[t]} messages lost "
                                f"({got} read)")
        else:
            warnings.append(f"{path}: topic {t}: {got} messages read; how many were lost is unknown "
                            "(no metadata.yaml count)")
    return Salvaged(topics, messages, warnings + [n for n in notes if "\n" not in n][:5])
