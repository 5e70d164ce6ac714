"""A camera calibration campaign of a URDF robot as a real ROS 2 bag: JointState, the camera's images
(``sensor_msgs/msg/Image`` or ``CompressedImage``) and its ``CameraInfo`` (tests, benchmarks, examples).

The robot moves from stop to stop and dwells (`pipeline.simulate.ros2_bag.timeline`); the camera
takes one image in the middle of each dwell (and, for `moving`, one mid-move), rendered by OpenCV
from the robot's true pose then (`pipeline.simulate.camera_images.render`).  The camera's clock is
`clock_offset_s` ahead of the controller's (its header stamps and receive times).  Every message is
serialised by rosbags' CDR serialiser and written with its rosbag2 `Writer`.  Damage on purpose:
`bad` maps an image record to ``corrupt`` (compressed bytes that are not an image), ``encoding``
(an encoding robocal does not read) or ``size`` (half the size CameraInfo says); and images that are
fine input but useless: ``blank`` (no board in it), ``blur`` (out of focus).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.simulate.ros2_bag import JOINT_STATE, T0_NS, BagLayout, _header, timeline

IMAGE, COMPRESSED, CAMERA_INFO = "sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage", "sensor_msgs/msg/CameraInfo"


@dataclass(frozen=True)
class CameraBagLayout:
    """Timing (s, Hz), topics and the images' form: `encoding` mono8 | bgr8 | rgb8 (Image) or jpeg |
    png (CompressedImage); `info_k` the K/D CameraInfo states (None: no CameraInfo topic)."""

    rate_hz: float = 50.0
    move_s: float = 1.0
    dwell_s: float = 1.5
    encoding: str = "mono8"
    image_topic: str = "/camera/image_raw"
    info_topic: str = "/camera/camera_info"
    info_k: tuple | None = ()  # () : the truth's intrinsics; None: no CameraInfo
    clock_offset_s: float = 0.0
    moving: tuple[int, ...] = ()
    bad: dict[int, str] = field(default_factory=dict)
    blur_px: float = 0.6
    noise: float = 2.0


def _image_msg(store, hdr, img: np.ndarray, encoding: str, damage: str | None):
    import cv2

    T = store.types
    if damage == "size":
        img = cv2.resize(img, (img.shape[1] // 2, img.shape[0] // 2), interpolation=cv2.INTER_AREA)
    elif damage == "blank":  # the lens cap on: no board
        img = np.full_like(img, 128)
    elif damage == "blur":  # out of focus: edges ≈ 2.56 σ wide (10–90 %)
        img = cv2.GaussianBlur(img, (0, 0), 2.5)
    if encoding in ("jpeg", "png"):
        ok, buf = cv2.imencode("." + ("jpg" if encoding == "jpeg" else "png"), img)
        data = np.frombuffer(buf, np.uint8).copy()
        if damage == "corrupt":
            data = data[: len(data) // 3].copy()
            data[8:] = 0
        return T[COMPRESSED](header=hdr, format=encoding, data=data), COMPRESSED
    h, w = img.shape
    enc = "yuv422" if damage == "encoding" else encoding
    if encoding == "mono8":
        data, step = img.ravel(), w
    else:
        data, step = np.repeat(img[:, :, None], 3, axis=2).ravel(), 3 * w  # grey in colour: B = G = R
    if damage == "encoding":
        data, step = np.ascontiguousarray(img.repeat(2, axis=1)).ravel(), 2 * w
    return T[IMAGE](header=hdr, height=h, width=w, encoding=enc, is_bigendian=0, step=step,
                    data=np.ascontiguousarray(data, np.uint8)), IMAGE


def _info_msg(store, hdr, k: np.ndarray, size: tuple[int, int]):
    T = store.types
    K = np.array([[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1.0]])
    d = np.asarray(k[4:], float)  # K all zero: an uncalibrated camera (its D empty)
    P = np.c_[K, np.zeros(3)]
    return T[CAMERA_INFO](header=hdr, height=size[1], width=size[0],
                          distortion_model="rational_polynomial" if len(d) == 8 else "plumb_bob",
                          d=d, k=K.ravel(), r=np.eye(3).ravel(), p=P.ravel(), binning_x=0, binning_y=0,
                          roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                                    do_rectify=False))


def write_camera_bag(out: str | Path, model, x: np.ndarray, q_stops: np.ndarray, target, rng: np.random.Generator,
                     layout: CameraBagLayout = CameraBagLayout(), storage: str = "mcap",
                     images: list[np.ndarray] | None = None) -> dict:
    """Render and write the bag folder `out` for the camera measurement model `model` at truth `x`,
    stops `q_stops` (m, J); returns the truth of the timing: ``t_image_s`` (camera clock, s from the
    bag start), ``q_image`` (true joint positions at each image), the storage file, and ``images``
    (the rendered grey images, to pass back as `images` for another bag of the same stops and timing)."""
    from pipeline.simulate import camera_images as ci

    k_true = model.split(x)[1]
    rays = ci.rays(k_true, model.lens, model.image_size) if images is None else None

    def image_of(i: int, q_image: np.ndarray) -> np.ndarray:
        if images is not None:
            return images[i]
        T = ci.board_in_camera(model, x, q_image[None])[0]
        return ci.render(k_true, model.lens, T, target, model.image_size, layout.blur_px, layout.noise, rng,
                         ray_table=rays)

    info_k = None if layout.info_k is None else (np.asarray(k_true) if layout.info_k == () else np.asarray(layout.info_k))
    return write_images_bag(out, list(model.kin.joint_names), q_stops, image_of, model.image_size, info_k, layout,
                            storage)


def write_images_bag(out: str | Path, joint_names: list[str], q_stops: np.ndarray, image_of, size: tuple[int, int],
                     info_k: np.ndarray | None, layout: CameraBagLayout = CameraBagLayout(),
                     storage: str = "mcap") -> dict:
    """Write the bag folder `out`: the robot moving between `q_stops` (m, J; joints `joint_names`),
    one image a stop, `image_of(i, q)` the grey image (h, w) at stop i seen from joint positions q;
    CameraInfo of `size` (width, height px) with intrinsics `info_k` (zeros: an uncalibrated camera;
    None: no CameraInfo).  Returns the timing as `write_camera_bag`."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    from pipeline.ros2.images import typestore

    store = typestore()
    bl = BagLayout(rate_hz=layout.rate_hz, move_s=layout.move_s, dwell_s=layout.dwell_s)
    t, q, t_dwell, t_move = timeline(np.asarray(q_stops, float), bl)
    ti = t_dwell.copy()
    mv = np.array(layout.moving, int)
    ti[mv] = t_move[mv]
    qi = q[np.abs(t[None, :] - ti[:, None]).argmin(1)]  # the robot's true pose at each image (the nearest sample)
    rendered: list[np.ndarray] = []
    tj = T0_NS + np.round(t * 1e9).astype(np.int64)
    tc = T0_NS + np.round((ti + layout.clock_offset_s) * 1e9).astype(np.int64)
    events = sorted([(int(s), 0, i) for i, s in enumerate(tj)] + [(int(s), 1, i) for i, s in enumerate(tc)])
    compressed = layout.encoding in ("jpeg", "png")
    topic = layout.image_topic + ("/compressed" if compressed and not layout.image_topic.endswith("compressed") else "")
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    empty = np.zeros(0)
    with Writer(Path(out), version=9, storage_plugin=plugin) as w:
        cj = w.add_connection("/joint_states", JOINT_STATE, typestore=store)
        ci_ = w.add_connection(topic, COMPRESSED if compressed else IMAGE, typestore=store)
        cinfo = w.add_connection(layout.info_topic, CAMERA_INFO, typestore=store) if info_k is not None else None
        for s, kind, i in events:
            if kind == 0:
                msg = store.types[JOINT_STATE](header=_header(store, s), name=list(joint_names), position=q[i],
                                               velocity=empty, effort=empty)
                w.write(cj, s, bytes(store.serialize_cdr(msg, JOINT_STATE)))
                continue
            hdr = _header(store, s, "camera_optical_frame")
            img = image_of(i, qi[i])
            rendered.append(img)
            msg, typ = _image_msg(store, hdr, img, layout.encoding, layout.bad.get(i))
            w.write(ci_, s, bytes(store.serialize_cdr(msg, typ)))
            if cinfo is not None:
                w.write(cinfo, s, bytes(store.serialize_cdr(_info_msg(store, hdr, info_k, size), CAMERA_INFO)))
    return {"t_image_s": ti + layout.clock_offset_s, "q_image": qi, "topic": topic, "images": rendered,
            "storage": Path(out) / f"{Path(out).name}.{'mcap' if storage == 'mcap' else 'db3'}"}
