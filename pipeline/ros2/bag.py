"""A ROS 2 bag opened once for one import: its topics and their messages, streamed from rosbags' reader (the
bag stays open for a second pass over the same reader: a camera's paired images), or — where rosbags cannot
open or read the bag (a recorder killed before it wrote the MCAP footer and metadata.yaml, a copy cut short)
— the messages salvaged from its storage files (`pipeline.ros2.salvage`), the loss named in `warnings`.

Messages are handed out as raw CDR bytes with their topic and receive time (ns); each reader decodes what it
needs once (`pipeline.ros2.messages`).  The robot's description, where the bag carries it on
``/robot_description`` (``std_msgs/msg/String``, latched by ``robot_state_publisher``), is read from the same
open bag (`description`).
"""

from __future__ import annotations

import heapq
from pathlib import Path
from typing import Callable, Iterator, TypeVar

from pipeline.errors import RobocalError

T = TypeVar("T")
DESCRIPTION_TOPIC = "/robot_description"
STRING = "std_msgs/msg/String"


class Damaged(RobocalError):
    """rosbags cannot open or read on: the storage is damaged (its messages may be salvaged)."""

    def __init__(self, message: str, why: str) -> None:
        super().__init__(message)
        self.why = why


class Bag:
    """One bag, opened once (module docstring): `topics` (topic → type), `messages(topics)`, `read(fn)`."""

    def __init__(self, path: str | Path) -> None:
        from rosbags.rosbag2 import Reader

        self.path = Path(path)
        self.reader = None
        self.salvaged = None
        self.warnings: list[str] = []
        self.data_lost: list[str] = []
        try:
            reader = Reader(self.path)
            reader.open()
        except Exception as e:  # noqa: BLE001 — any failure of the storage layer is the file's problem
            why = f"{type(e).__name__}: {e}"
            self._salvage(why, f"{self.path}: cannot read as a ROS 2 bag ({why})")
            return
        self.reader = reader
        self.topics = {t: (info.msgtype or "(several types)") for t, info in reader.topics.items()}

    def _salvage(self, why: str, message: str) -> None:
        from pipeline.ros2.salvage import salvage

        self.close()
        self.salvaged = salvage(self.path, why, message)
        self.topics = self.salvaged.topics
        self.warnings += self.salvaged.warnings
        self.data_lost = self.salvaged.warnings  # the bag's damage: ingest's status is then warn, never pass

    def messages(self, topics) -> Iterator[tuple[str, int, bytes]]:
        """(topic, receive time ns, CDR bytes) of `topics` in bag order, one message at a time; a storage
        failure part-way is `Damaged`, saying how far the bag was read."""
        wanted = set(topics)
        if self.salvaged is not None:
            streams = [[(t, tp, d) for t, d in self.salvaged.messages.get(tp, [])] for tp in sorted(wanted)]
            for t, tp, d in heapq.merge(*streams, key=lambda m: m[0]):
                yield tp, t, d
            return
        it = self.reader.messages(connections=[c for c in self.reader.connections if c.topic in wanted])
        n = 0
        while True:
            try:
                conn, t, data = next(it)
            except StopIteration:
                return
            except Exception as e:  # noqa: BLE001 — the storage layer's failure is the file's problem
                why = f"{type(e).__name__}: {e}"
                raise Damaged(f"{self.path}: cannot read the bag after message {n} ({why})",
                              f"read stops after message {n}: {why}") from None
            n += 1
            yield conn.topic, t, data

    def read(self, fn: Callable[["Bag"], T]) -> T:
        """`fn(self)`; when the storage fails part-way, once more on the messages salvaged from it."""
        try:
            return fn(self)
        except Damaged as e:
            if self.salvaged is not None:
                raise
            self._salvage(e.why, str(e))
            return fn(self)

    def description(self) -> str | None:
        """The URDF text of the bag's first ``/robot_description`` message, or None when it has none."""
        if self.topics.get(DESCRIPTION_TOPIC) != STRING:
            return None
        from pipeline.ros2.messages import _decoder

        decode = _decoder(self.path, DESCRIPTION_TOPIC, STRING)
        for _, _, data in self.messages([DESCRIPTION_TOPIC]):
            return str(decode(0, data).data)
        return None

    def close(self) -> None:
        if self.reader is not None:
            self.reader.close()
            self.reader = None

    def __enter__(self) -> "Bag":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
