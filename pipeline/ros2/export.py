"""A robocal recording → a ROS 2 bag (`robocal export ros2 REC.mcap --out BAG_DIR`): what ``ros2 bag
play``, RViz, Foxglove and rerun read as they read a robot's own bag.

Written by rosbags' rosbag2 ``Writer`` (format version 9, MCAP storage, CDR by its typestore of the
standard message definitions), every message stamped (``header.stamp`` and receive time) with the
recording's own times:

- ``/robot_description`` ``std_msgs/msg/String``: the robot's URDF, once, offered as
  ``robot_state_publisher`` offers it (reliable, transient local, keep last 1: a late subscriber still
  gets it);
- ``/tf_static`` ``tf2_msgs/msg/TFMessage``: every fixed joint of the URDF, the root link →
  ``robocal_instrument`` and the tip → ``robocal_tool`` (`pipeline.ros2.frames`), once, transient local
  as tf2's static broadcaster offers it;
- ``/joint_states`` ``sensor_msgs/msg/JointState``: the encoder stream (positions, and velocities /
  efforts where recorded) or, without one, each measurement's posture; ``/tf``: the chain's movable
  joints at each of those postures (as ``robot_state_publisher`` publishes them);
- the measurements as the closest standard messages, in frame ``robocal_instrument``: point →
  ``geometry_msgs/msg/PointStamped`` (``/measure/point``, or ``/measure/point/<tip>`` per measured tip),
  pose → ``geometry_msgs/msg/PoseStamped`` (``/measure/pose``), camera → ``sensor_msgs/msg/CameraInfo``
  (``/camera/camera_info``: the image size and the campaign's starting intrinsics) and, where the
  recording keeps the image, ``sensor_msgs/msg/Image`` (``/camera/image_raw``, mono8 or bgr8).

Channels no standard message carries (planes, coincidences, contacts, robocal's own metadata) are
named in the result as not exported.  The bag folder is marked as robocal's (metadata.yaml
``custom_data``: ``robocal.writer``, ``robocal.source``): an existing folder is replaced only when
robocal wrote it and with ``force`` (kept as NAME.bak; `pipeline.recording.output`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError
from pipeline.recording.scene import INSTRUMENT_FRAME

STRING, TF, JOINT_STATE = "std_msgs/msg/String", "tf2_msgs/msg/TFMessage", "sensor_msgs/msg/JointState"
POINT, POSE = "geometry_msgs/msg/PointStamped", "geometry_msgs/msg/PoseStamped"
IMAGE, CAMERA_INFO = "sensor_msgs/msg/Image", "sensor_msgs/msg/CameraInfo"
EXPORTED = ("/measure/point", "/measure/pose", "/measure/camera", "/robot/joint_state", "/tf", "/robot_description")


@dataclass
class Exported:
    """What one export wrote: topic → (message type, count), and the channels left out with why."""

    out: Path
    topics: dict[str, tuple[str, int]] = field(default_factory=dict)
    left_out: list[str] = field(default_factory=list)


def _qos(depth: int, latched: bool):
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    never = QosTime(9223372036, 854775807)  # rmw's infinite duration, as `ros2 bag record` writes it
    return [Qos(QosHistory.KEEP_LAST, depth, QosReliability.RELIABLE,
                QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE, never, never,
                QosLiveliness.AUTOMATIC, never, False)]


class _Bag:
    """The rosbags writer with one connection per topic and the standard typestore."""

    def __init__(self, out: Path, source: Path) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore

        from pipeline import __version__
        from pipeline.recording.output import BAG_MARK

        self.store = get_typestore(Stores.LATEST)
        self.T = self.store.types
        self.writer = Writer(out, version=9, storage_plugin=StoragePlugin.MCAP)
        self.writer.set_custom_data(BAG_MARK, f"robocal/{__version__}")
        self.writer.set_custom_data("robocal.source", str(source))
        self.writer.open()
        self.conns: dict[str, object] = {}
        self.counts: dict[str, tuple[str, int]] = {}

    def write(self, topic: str, typename: str, t_ns: int, msg, depth: int = 10, latched: bool = False) -> None:
        if topic not in self.conns:
            self.conns[topic] = self.writer.add_connection(topic, typename, typestore=self.store,
                                                           offered_qos_profiles=_qos(depth, latched))
        self.writer.write(self.conns[topic], int(t_ns), self.store.serialize_cdr(msg, typename))
        self.counts[topic] = (typename, self.counts.get(topic, (typename, 0))[1] + 1)

    def header(self, t_ns: int, frame: str = ""):
        t = int(t_ns)
        return self.T["std_msgs/msg/Header"](stamp=self.T["builtin_interfaces/msg/Time"](
            sec=t // 1_000_000_000, nanosec=t % 1_000_000_000), frame_id=frame)

    def transforms(self, t_ns: int, pairs, mats: np.ndarray, quats: np.ndarray | None = None):
        """A TFMessage of parent → child `pairs` with transforms `mats` (K, 4, 4) (their quaternions x, y, z,
        w (K, 4) when computed already)."""
        from scipy.spatial.transform import Rotation

        T = self.T
        if quats is None:
            quats = Rotation.from_matrix(mats[:, :3, :3]).as_quat() if len(pairs) else np.zeros((0, 4))
        return T[TF](transforms=[T["geometry_msgs/msg/TransformStamped"](
            header=self.header(t_ns, a), child_frame_id=b, transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](*map(float, M[:3, 3])),
                rotation=T["geometry_msgs/msg/Quaternion"](*map(float, qt))))
            for (a, b), M, qt in zip(pairs, mats, quats)])


def _joint_stream(rec, names: list[str]):
    """(t_ns (T,), q (T, J), velocity or None, effort or None) of the encoder stream in `names` order, or None."""
    from pipeline.recording import joint_state_batch as JSB
    from pipeline.recording.schemas import STREAM

    raw = rec.messages.raw.get(STREAM)
    if not raw or rec.encodings.get(STREAM) != "protobuf":
        return None
    b = JSB.decode(raw)
    if not set(names) <= set(b.names):
        return None
    idx = [b.names.index(n) for n in names]
    pick = lambda a: None if a is None else np.ascontiguousarray(np.asarray(a, float)[:, idx])  # noqa: E731
    return np.asarray(b.t_ns, np.int64), pick(b.q), pick(b.velocity), pick(b.effort)


def _attachments(path: Path) -> dict[str, bytes]:
    """The recording's attachments by name (a camera recording's kept images); {} when it has none."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            return {a.name: bytes(a.data) for a in make_reader(f).iter_attachments()}
    except Exception:  # noqa: BLE001 — no summary (a damaged file): the images are left out, the rest exported
        return {}


def _image(images: dict[str, bytes], name: str):
    """The grey or colour pixels of a camera recording's kept image `name`, or None."""
    data = images.get(name)
    if data is None:
        return None
    import cv2

    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    return img if img is not None and img.dtype == np.uint8 else None


def export_bag(recording: str | Path, out: str | Path, force: bool = False) -> Exported:
    """Write the recording `recording` as the ROS 2 bag folder `out` (module docstring)."""
    from pipeline.recording.output import check_bag_output, claim_bag_output
    from pipeline.recording.reader import read_recording
    from pipeline.recording.schemas import META_CAMPAIGN
    from pipeline.ros2.frames import robot_frames

    recording, out = Path(recording), Path(out)
    check_bag_output(out, force)
    rec = read_recording(recording)
    robot = robot_frames(rec.metadata)
    if robot is None:
        raise RobocalError(f"{recording}: the robot has no serial chain robocal can publish as /tf (a Delta); "
                           "nothing to export")
    camp = rec.metadata.get(META_CAMPAIGN) or {}
    names = robot.joint_names
    meas = {t: rec.messages[t] for t in ("/measure/point", "/measure/pose", "/measure/camera") if rec.messages.raw.get(t)}
    postures_t, postures_q = [], []
    for msgs in meas.values():
        postures_t += [int(m["timestamp_ns"]) for m in msgs]
        postures_q += [m["joint_positions"] for m in msgs]
    stream = _joint_stream(rec, names)
    if stream is None and not postures_t:
        raise RobocalError(f"{recording}: no measurements and no encoder stream: no posture to export")
    result = Exported(out)
    result.left_out = sorted(t for t in rec.messages.raw if t not in EXPORTED and rec.messages.raw[t])
    claim_bag_output(out, force)
    bag = _Bag(out, recording)
    try:
        t_first = min(([int(stream[0][0])] if stream is not None else []) + postures_t)
        bag.write("/robot_description", STRING, t_first, bag.T[STRING](data=robot.urdf), depth=1, latched=True)
        bag.write("/tf_static", TF, t_first, bag.transforms(t_first, [(a, b) for a, b, _ in robot.static],
                                                            np.array([M for _, _, M in robot.static])),
                  depth=1, latched=True)
        events = _events(bag, robot, stream, postures_t, postures_q, meas, camp, rec)
        for t, topic, typename, msg in sorted(events, key=lambda e: e[0]):
            bag.write(topic, typename, t, msg, depth=100 if topic == "/tf" else 10)
    except BaseException:
        bag.writer.close()
        raise
    bag.writer.close()
    result.topics = dict(bag.counts)
    return result


def _events(bag: _Bag, robot, stream, postures_t, postures_q, meas: dict, camp: dict, rec) -> list:
    """(t_ns, topic, type, message) of the joint states, /tf and the measurements."""
    T = bag.T
    names = robot.joint_names
    if stream is not None:
        t, q, v, e = stream
    else:
        order = np.argsort(postures_t, kind="stable")
        t, q, v, e = np.asarray(postures_t, np.int64)[order], np.asarray(postures_q, float)[order], None, None
    from scipy.spatial.transform import Rotation

    out = []
    pairs, F = robot.moving(q)
    quats = Rotation.from_matrix(F[..., :3, :3].reshape(-1, 3, 3)).as_quat().reshape(*F.shape[:2], 4)
    for i in range(len(t)):
        js = T[JOINT_STATE](header=bag.header(t[i]), name=list(names), position=q[i].astype(float),
                            velocity=np.zeros(0) if v is None else v[i], effort=np.zeros(0) if e is None else e[i])
        out.append((int(t[i]), "/joint_states", JOINT_STATE, js))
        out.append((int(t[i]), "/tf", TF, bag.transforms(int(t[i]), pairs, F[i], quats[i])))
    tips = (rec.metadata.get("robocal.urdf") or {}).get("tips") or []
    for m in meas.get("/measure/point", []):
        k = int(m.get("target", 0))
        topic = f"/measure/point/{tips[k]}" if len(tips) > 1 and k < len(tips) else "/measure/point"
        p = T["geometry_msgs/msg/Point"](*map(float, m["position"]))
        out.append((int(m["timestamp_ns"]), topic, POINT, T[POINT](header=bag.header(m["timestamp_ns"], INSTRUMENT_FRAME),
                                                                    point=p)))
    for m in meas.get("/measure/pose", []):
        pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](*map(float, m["position"])),
                                           orientation=T["geometry_msgs/msg/Quaternion"](*map(float, m["orientation"])))
        out.append((int(m["timestamp_ns"]), "/measure/pose", POSE,
                    T[POSE](header=bag.header(m["timestamp_ns"], INSTRUMENT_FRAME), pose=pose)))
    images = _attachments(rec.path) if meas.get("/measure/camera") else {}
    for m in meas.get("/measure/camera", []):
        out += _camera(bag, m, camp, images)
    return out


def _camera(bag: _Bag, m: dict, camp: dict, images: dict[str, bytes]) -> list:
    """CameraInfo (the image size, the campaign's starting intrinsics) and, where kept, the image."""
    T = bag.T
    t, w, h = int(m["timestamp_ns"]), int(m["width"]), int(m["height"])
    k0 = camp.get("start_intrinsics") or []
    K = np.zeros(9)
    if len(k0) >= 4:
        K = np.array([k0[0], 0, k0[2], 0, k0[1], k0[3], 0, 0, 1], float)
    lens = camp.get("lens", "pinhole")
    d = np.asarray(k0[4:] if len(k0) > 4 else [], float)
    model = "equidistant" if lens == "fisheye" else ("rational_polynomial" if len(d) > 5 else "plumb_bob")
    P = np.zeros(12)
    P[[0, 2, 5, 6, 10]] = K[[0, 2, 4, 5, 8]]
    info = T[CAMERA_INFO](header=bag.header(t, "camera"), height=h, width=w, distortion_model=model, d=d, k=K,
                          r=np.eye(3).ravel(), p=P, binning_x=0, binning_y=0,
                          roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                                    do_rectify=False))
    out = [(t, "/camera/camera_info", CAMERA_INFO, info)]
    img = _image(images, str(m.get("image", "")))
    if img is not None:
        enc, ch = ("mono8", 1) if img.ndim == 2 else ("bgr8", 3)
        out.append((t, "/camera/image_raw", IMAGE, T[IMAGE](header=bag.header(t, "camera"), height=img.shape[0],
                                                             width=img.shape[1], encoding=enc, is_bigendian=0,
                                                             step=img.shape[1] * ch, data=img.reshape(-1))))
    return out
