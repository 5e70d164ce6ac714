"""ROS 2 camera messages → what the camera calibration reads: ``sensor_msgs/msg/Image`` and
``CompressedImage`` decoded to 8-bit grey images, ``CameraInfo`` to the image size (px) and the
intrinsics vector of `pipeline.camera.projection` (fx, fy, cx, cy px, then OpenCV's distortion terms).

Image encodings read: ``mono8`` / ``8UC1``, ``mono16`` / ``16UC1`` (scaled to 8 bits), ``bgr8`` /
``8UC3``, ``rgb8``, ``bgra8`` / ``8UC4``, ``rgba8``; compressed ``jpeg`` and ``png`` (decoded by
OpenCV's ``imdecode``).  A message that cannot be read gives a status and a reason, never an
exception: ``unsupported encoding``, ``unreadable`` (corrupt data or CDR), ``too large`` (a compressed
image whose header states more pixels than `pipeline.camera.detect.MAX_PIXELS`: not decoded),
``wrong size`` (not the size CameraInfo says).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
IMAGE_TYPES = (IMAGE, COMPRESSED)
CHANNELS = {"mono8": 1, "8uc1": 1, "mono16": 1, "16uc1": 1, "bgr8": 3, "8uc3": 3, "rgb8": 3, "bgra8": 4, "8uc4": 4,
            "rgba8": 4}
ENCODINGS = "mono8, mono16, bgr8, rgb8, bgra8, rgba8 (8UC1/16UC1/8UC3/8UC4)"
# CameraInfo.distortion_model → (robocal lens, number of OpenCV distortion terms it carries)
DISTORTION_MODELS = {"plumb_bob": ("pinhole", 5), "rational_polynomial": ("pinhole", 8), "equidistant": ("fisheye", 4)}


@lru_cache(maxsize=1)
def typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.LATEST)


def header_stamp(data: bytes) -> int | None:
    """A stamped message's ``header.stamp`` (ns) read straight from its CDR bytes (4-byte
    encapsulation header, then int32 sec, uint32 nanosec: the first field of every message with a
    header), without decoding the rest (an image's pixels); None when the bytes are too short."""
    if len(data) < 12 or data[1] not in (0, 1):
        return None
    sec, nsec = struct.unpack_from("<iI" if data[1] == 1 else ">iI", data, 4)
    return int(sec) * 1_000_000_000 + int(nsec)


def grey(msg, typename: str) -> tuple[np.ndarray | None, str, str]:
    """(8-bit grey image (h, w) or None, status, reason) of a decoded Image / CompressedImage."""
    import cv2

    if typename == COMPRESSED:
        fmt = str(msg.format).lower()
        if "compresseddepth" in fmt:
            return None, "unsupported encoding", f"compressed format {msg.format!r} (depth) is not a camera image"
        buf = np.asarray(msg.data, np.uint8)
        import io

        from pipeline.camera.detect import header_size, too_large

        if (why := too_large(header_size(io.BytesIO(buf.tobytes())))) is not None:
            return None, "too large", why  # judged from the header, never decoded
        img = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE) if buf.size else None
        if img is None:
            return None, "unreadable", f"{len(buf)} bytes of {msg.format or 'compressed'} data OpenCV cannot decode (corrupt)"
        return img, "ok", ""
    enc = str(msg.encoding)
    ch = CHANNELS.get(enc.lower())
    if ch is None:
        return None, "unsupported encoding", f"encoding {enc!r} is not read (read: {ENCODINGS})"
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    depth = 2 if "16" in enc else 1
    data = np.asarray(msg.data, np.uint8)
    if h == 0 or w == 0 or step < w * ch * depth or data.size < step * h:
        return None, "unreadable", (f"{w}x{h} px {enc} needs {w * ch * depth} bytes a row and {step * h} in all; "
                                    f"step {step}, {data.size} bytes")
    rows = data[:step * h].reshape(h, step)[:, :w * ch * depth]
    if depth == 2:
        v = rows.reshape(h, w, 2).view(">u2" if msg.is_bigendian else "<u2")[:, :, 0]
        return (v >> 8).astype(np.uint8), "ok", ""
    img = np.ascontiguousarray(rows.reshape(h, w, ch))
    code = {3: cv2.COLOR_RGB2GRAY if enc.lower() == "rgb8" else cv2.COLOR_BGR2GRAY,
            4: cv2.COLOR_RGBA2GRAY if enc.lower() == "rgba8" else cv2.COLOR_BGRA2GRAY}.get(ch)
    return (img[:, :, 0] if code is None else cv2.cvtColor(img, code)), "ok", ""


@dataclass(frozen=True)
class CameraInfo:
    """What a CameraInfo message says: the image size (px), its distortion model, and the
    intrinsics (fx, fy, cx, cy px; distortion terms in OpenCV's order) — None when K is all zero
    (an uncalibrated camera's CameraInfo)."""

    width: int
    height: int
    distortion_model: str
    k: np.ndarray | None

    @property
    def size(self) -> tuple[int, int]:
        return self.width, self.height


def camera_info(msg) -> CameraInfo:
    """The `CameraInfo` of a decoded ``sensor_msgs/msg/CameraInfo``."""
    K = np.asarray(msg.k, float).reshape(3, 3)
    model = str(msg.distortion_model)
    k = None
    if np.all(np.isfinite(K)) and K[0, 0] > 0 and K[1, 1] > 0:
        k = np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], np.asarray(msg.d, float)]
        if not np.all(np.isfinite(k)):
            k = None
    return CameraInfo(int(msg.width), int(msg.height), model, k)


def start_intrinsics(info: CameraInfo, lens: str, n_dist: int) -> list[float] | None:
    """The intrinsics vector (4 + n_dist) of `lens` that `info` gives as the calibration's start:
    its K, and its D where the distortion model is `lens`'s (zeros past the terms it has);
    None when it gives no K."""
    if info.k is None:
        return None
    d = np.zeros(n_dist)
    same = DISTORTION_MODELS.get(info.distortion_model, ("", 0))[0] == lens
    if same:
        have = info.k[4:4 + n_dist]
        d[:len(have)] = have
    return [float(v) for v in np.r_[info.k[:4], d]]


def decode_image(typename: str, data: bytes, size: tuple[int, int] | None) -> tuple[np.ndarray | None, str, str]:
    """(grey image or None, status, reason) of one image message's CDR bytes, checked against `size`."""
    try:
        msg = typestore().deserialize_cdr(data, typename)
    except Exception as e:  # noqa: BLE001 — the library's errors (SerdeError, struct, …) are the data's
        return None, "unreadable", f"CDR does not decode as {typename} ({type(e).__name__}: {e})"
    img, status, reason = grey(msg, typename)
    if img is not None and size is not None and (img.shape[1], img.shape[0]) != tuple(size):
        return None, "wrong size", f"{img.shape[1]}x{img.shape[0]} px, CameraInfo says {size[0]}x{size[1]} px"
    return img, status, reason
