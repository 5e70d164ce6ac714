"""Writing recordings: `RecordingWriter` wraps `mcap.writer.Writer` with robocal's channels."""

from __future__ import annotations

import json
from pathlib import Path
from typing import IO, Any

import numpy as np
from mcap.writer import CompressionType, Writer

from pipeline import __version__
from pipeline.recording import joint_state_batch as JSB
from pipeline.recording.schemas import CHANNELS, STREAM, schema_bytes, schema_title

PROFILE = "robocal"


def jsonable(o: Any) -> Any:
    """`json.dumps` default for numpy values: arrays become lists, scalars Python numbers."""
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    raise TypeError(f"cannot encode {type(o).__name__}")


def encode(msg: dict) -> bytes:
    """Compact JSON (numpy arrays become lists)."""
    return json.dumps(msg, separators=(",", ":"), default=jsonable, allow_nan=False).encode()


class RecordingWriter:
    """MCAP writer with one channel per robocal topic: JSON with its JSON Schema, except the encoder
    stream (`/robot/joint_state`), protobuf `robocal.JointStateBatch` with its FileDescriptorSet
    (`stream_encoding="json"` writes it as archived recordings have it, for tests and comparisons).

    Chunks are closed every `chunk_size` bytes; call `flush_chunk()` to force one out (the
    acquisition does so every second so a killed process loses at most that much).  `origin` is
    appended to the header's library ("robocal/<version> acquire": real measurements, which no
    command replaces; `pipeline.recording.output`).
    """

    def __init__(self, out: str | Path | IO[bytes], chunk_size: int = 1 << 20,
                 compression: CompressionType = CompressionType.ZSTD, stream_encoding: str = JSB.ENCODING,
                 scene: bool = False, origin: str = ""):
        if stream_encoding not in (JSB.ENCODING, "json"):
            raise ValueError(f"stream_encoding {stream_encoding!r}: 'protobuf' or 'json'")
        self.stream_encoding = stream_encoding
        self._own = not hasattr(out, "write")
        if self._own:
            from pipeline.recording.output import check_output

            check_output(out)
        self._f = open(out, "wb") if self._own else out
        self._w = Writer(self._f, chunk_size=chunk_size, compression=compression)
        self._w.start(profile=PROFILE, library=f"robocal/{__version__}" + (f" {origin}" if origin else ""))
        self._channels: dict[str, int] = {}
        self._seq: dict[str, int] = {}
        self._closed = False
        # scene=True (a recording written as it comes, e.g. the acquisition): the robot's /tf and
        # /robot_description are added at close from the metadata and the encoder stream written
        self._scene: dict | None = {"meta": {}, "t": [], "q": []} if scene else None

    def channel(self, topic: str) -> int:
        if topic not in self._channels and topic == STREAM and self.stream_encoding == JSB.ENCODING:
            sid = self._w.register_schema(name=JSB.SCHEMA_NAME, encoding=JSB.ENCODING, data=JSB.FILE_DESCRIPTOR_SET)
            self._channels[topic] = self._w.register_channel(topic=topic, message_encoding=JSB.ENCODING, schema_id=sid)
            self._seq[topic] = 0
        if topic not in self._channels:
            stem = CHANNELS[topic]
            sid = self._w.register_schema(name=schema_title(stem), encoding="jsonschema", data=schema_bytes(stem))
            self._channels[topic] = self._w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
            self._seq[topic] = 0
        return self._channels[topic]

    def write(self, topic: str, msg: dict, log_time_ns: int | None = None) -> None:
        """Write one message; `log_time` defaults to the message's `timestamp_ns`.  On the protobuf
        encoder stream `msg` is a batch in its JSON form (`joint_state_batch.from_dict`)."""
        from pipeline.recording.scene import SCENE_CHANNELS

        if topic in SCENE_CHANNELS:  # /tf, /robot_description: no timestamp_ns of their own
            self.write_scene(topic, msg, int(log_time_ns))
            return
        cid = self.channel(topic)
        t = int(msg["timestamp_ns"] if log_time_ns is None else log_time_ns)
        data = JSB.from_dict(msg) if topic == STREAM and self.stream_encoding == JSB.ENCODING else encode(msg)
        self._add(topic, cid, t, int(msg["timestamp_ns"]), data)

    def _add(self, topic: str, cid: int, log_time: int, publish_time: int, data: bytes) -> None:
        self._seq[topic] += 1
        self._w.add_message(cid, log_time=log_time, data=data, publish_time=publish_time, sequence=self._seq[topic])

    def write_scene(self, topic: str, msg: dict, log_time_ns: int) -> None:
        """One message on a scene channel (`pipeline.recording.scene`: /tf, /robot_description),
        registered under the schema name Foxglove / ROS tools recognise."""
        from pipeline.recording import scene

        if topic not in self._channels:
            name, data = scene.scene_schema(topic)
            sid = self._w.register_schema(name=name, encoding="jsonschema", data=data)
            self._channels[topic] = self._w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
            self._seq[topic] = 0
        t = int(log_time_ns)
        self._add(topic, self._channels[topic], t, t, scene.encode(msg))
        if topic == scene.DESCRIPTION_TOPIC:  # the URDF also as a file inside the recording
            self._w.add_attachment(create_time=t, log_time=t, name=scene.ATTACHMENT, media_type="application/xml",
                                   data=msg["data"].encode())

    def write_batch(self, t_ns: np.ndarray, q: np.ndarray, names: list[str] | tuple[str, ...],
                    device_t_ns: np.ndarray | None = None, host_t_ns: np.ndarray | None = None,
                    q_cmd: np.ndarray | None = None, effort: np.ndarray | None = None,
                    current: np.ndarray | None = None, velocity: np.ndarray | None = None) -> None:
        """One encoder-stream message: samples `t_ns` (n,) ns, positions `q` (n, n_joints) rad,
        optional raw device and host receive times (n,) ns, optional drive state (n, n_joints):
        commanded positions rad / m, efforts N·m / N, motor currents A, logged velocities rad/s (protobuf
        only); log time = the first sample's."""
        t0 = int(t_ns[0])
        if self._scene is not None:
            self._scene["t"].append(np.asarray(t_ns, np.int64))
            self._scene["q"].append(np.asarray(q, float))
        if self.stream_encoding == JSB.ENCODING:
            self._add(STREAM, self.channel(STREAM), t0, t0,
                      JSB.encode(t_ns, q, names, device_t_ns, host_t_ns, q_cmd, effort, current, velocity))
            return
        if q_cmd is not None or effort is not None or current is not None or velocity is not None:
            raise ValueError("drive state (commanded positions, efforts, currents) is written on the protobuf stream only")
        msg = {"timestamp_ns": t0, "timestamps_ns": np.asarray(t_ns).tolist(), "joint_names": list(names),
               "positions": np.asarray(q).tolist()}
        for key, v in zip(JSB.OPTIONAL_TIMES, (device_t_ns, host_t_ns)):
            if v is not None:
                msg[key] = np.asarray(v).tolist()
        self.write(STREAM, msg)

    def metadata(self, name: str, value: dict | str) -> None:
        """A metadata record; dicts are stored as {'json': <compact JSON>}."""
        data = {"json": value if isinstance(value, str) else json.dumps(value, separators=(",", ":"), default=jsonable)}
        if self._scene is not None:  # documents arrive as JSON text from the devices
            try:
                self._scene["meta"][name] = json.loads(value) if isinstance(value, str) else value
            except ValueError:
                pass
        self._w.add_metadata(name, data)

    def attachment(self, name: str, data: bytes, media_type: str, log_time_ns: int = 0) -> None:
        """An MCAP attachment: a file's bytes kept unchanged (e.g. a calibration image)."""
        self._w.add_attachment(create_time=int(log_time_ns), log_time=int(log_time_ns), name=name,
                               media_type=media_type, data=data)

    def flush_chunk(self) -> None:
        """Close the open chunk and push it to the OS, so it survives a crash."""
        self._w.flush()

    def _write_scene_at_close(self) -> None:
        """The robot's frames along the stream written (scene=True); never at the cost of the recording."""
        from pipeline.recording.scene import scene_events

        sc, self._scene = self._scene, None
        if not sc or not sc["t"]:
            return
        try:
            events = scene_events(sc["meta"], (np.concatenate(sc["t"]), np.concatenate(sc["q"])))
        except Exception:  # noqa: BLE001 — a description that does not parse: the recording without /tf
            return
        for t, topic, msg in events:
            self.write_scene(topic, msg, t)

    def close(self) -> None:
        if not self._closed:
            self._write_scene_at_close()
            self._closed = True
            self._w.finish()
            if self._own:
                self._f.close()
            else:
                self._f.flush()

    def __enter__(self) -> "RecordingWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def joint_state_messages(t_ns: np.ndarray, q: np.ndarray, names: list[str] | tuple[str, ...],
                         batch: int = 250) -> list[dict]:
    """Split an encoder stream into batched `/robot/joint_state` message bodies.

    Positions are written with 1 nrad resolution (5·10⁴ times finer than a 2¹⁷-count
    encoder), which keeps the JSON compact and fast to ingest.
    """
    q = np.round(q, 9)
    out = []
    for s in range(0, t_ns.size, batch):
        t = t_ns[s:s + batch]
        out.append({"timestamp_ns": int(t[0]), "timestamps_ns": t.tolist(), "joint_names": list(names),
                    "positions": q[s:s + batch].tolist()})
    return out


def write_campaign(path: str | Path, metadata: dict[str, dict], stream: tuple[np.ndarray, np.ndarray, list[str]],
                   events: list[tuple[str, dict]], batch: int = 250, stream_encoding: str = JSB.ENCODING) -> None:
    """Write a whole campaign: metadata, the batched encoder stream (positions at 1 nrad
    resolution, as the archived JSON stream did, so both encodings carry the same numbers), the
    measurement events and the robot's frames and description for ROS / Foxglove tools
    (`pipeline.recording.scene`), all messages in log-time order."""
    from pipeline.recording.scene import scene_events

    t_ns, q, names = stream
    q = np.round(q, 9)
    starts = range(0, t_ns.size, batch)
    msgs = [(int(t_ns[s]), 0, STREAM, s) for s in starts] + [(int(m["timestamp_ns"]), 1, tp, m) for tp, m in events]
    msgs += [(t, 2, tp, m) for t, tp, m in scene_events(metadata, (t_ns, q))]  # the robot for ROS / Foxglove
    msgs.sort(key=lambda tm: tm[0])  # stable: a batch before an event of the same time, as before
    with RecordingWriter(path, stream_encoding=stream_encoding) as w:
        for name, value in metadata.items():
            w.metadata(name, value)
        for t, kind, topic, m in msgs:
            if kind == 0:
                w.write_batch(t_ns[m:m + batch], q[m:m + batch], names)
            elif kind == 1:
                w.write(topic, m)
            else:
                w.write_scene(topic, m, t)
