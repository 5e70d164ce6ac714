"""A ROS 2 bag with a camera → the detections of a camera calibration (`robocal import ros2 --target`).

Reads with **rosbags**: ``sensor_msgs/msg/JointState`` on the joint topic (as `pipeline.ros2.points`),
``sensor_msgs/msg/Image`` or ``CompressedImage`` on the image topic and ``sensor_msgs/msg/CameraInfo``
(the image size, and its K and D as the calibration's starting intrinsics).

Two passes over the bag, so that no more than a few images are held at once: the first reads the
joint states, the CameraInfo and each image's ``header.stamp`` (straight from the CDR bytes, the
pixels untouched); the second decodes and searches the board in the images that were paired, in a
process pool.

**Pairing and the clocks.** The camera's and the controller's clocks may disagree.  An image at
stamp t is paired with the joint states only when the robot stood still over
[t − B − w/2, t + B + w/2]: B the clock-offset bound (`clock_bound_s`, s), w the standstill window
(`pipeline.importers.standstill`); so any offset up to ±B pairs the image with the same still pose.
The offsets the data allow are reported too: over a grid of offsets δ (camera clock − joint clock),
whether every paired image stands still at t − δ: the range of δ around 0 where they all do is
what the data allow, its middle the offset estimate when the images were taken in the middle of
the stops.  Images taken while moving, or outside the joint states, are
listed and left out; images whose board is not found, partly found or blurred are listed with the
reason (`pipeline.camera.detect`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.camera.detect import MAX_EDGE_PX, Detection, detect_array, pool
from pipeline.errors import RobocalError
from pipeline.importers import standstill
from pipeline.ros2.points import (BagSpec, _topics_line, choose_joint_topic, split,
                                     read_joint_states)
from pipeline.ros2.images import (CAMERA_INFO, IMAGE_TYPES, camera_info, decode_image, header_stamp,
                                            typestore)
from pipeline.ros2.messages import _times, at

BAD = ("unreadable", "too large", "wrong size", "unsupported encoding")  # bad input: an error unless skip_bad


@dataclass(frozen=True)
class CameraSpec:
    """The camera side of a bag import: the target declaration (`pipeline.camera.targets`), the
    topics (None: the bag's only one), the mount (tip | world), the lens model, the clock-offset
    bound B (s) and a known offset (camera clock − joint clock, s, subtracted from image stamps)."""

    target: str
    image_topic: str | None = None
    info_topic: str | None = None
    mount: str = "tip"
    lens: str = "pinhole"
    n_dist: int = 8
    max_edge_px: float = MAX_EDGE_PX
    clock_bound_s: float = 0.1
    clock_offset_s: float = 0.0
    workers: int = 0
    skip_bad: bool = False
    kinematics_known: bool = False  # the joint states are exact (a measured flange pose's pose chain)


class _Stamps:
    """The `side` of `split`: keeps each image's stamp and receive time (not its bytes) and the
    CameraInfo messages' bytes."""

    def __init__(self, image_topic: str) -> None:
        self.image_topic = image_topic
        self.stamp: list[int] = []
        self.log: list[int] = []
        self.info: list[tuple[int, bytes]] = []

    def append(self, item) -> None:
        topic, t, data = item
        if topic == self.image_topic:
            s = header_stamp(data)
            self.stamp.append(-1 if s is None else s)
            self.log.append(t)
        else:
            self.info.append((t, data))


def choose_camera_topics(path: Path, topics: dict[str, str], cam: CameraSpec) -> tuple[str, str | None]:
    """(image topic, CameraInfo topic or None) checked against the bag's topic → type map; the
    CameraInfo topic by default the one beside the image topic (same namespace), else the only one."""
    imgs = sorted(t for t, ty in topics.items() if ty in IMAGE_TYPES)
    it = cam.image_topic
    if it is None:
        if len(imgs) != 1:
            raise RobocalError(f"{path}: {'several' if imgs else 'no'} sensor_msgs Image / CompressedImage topics "
                               f"({', '.join(imgs) or _topics_line(topics)}): name one with --image-topic")
        it = imgs[0]
    if it not in topics:
        raise RobocalError(f"{at(path, it)}: not in the bag; image topics: {', '.join(imgs) or 'none'} (--image-topic)")
    if topics[it] not in IMAGE_TYPES:
        raise RobocalError(f"{at(path, it)}: is {topics[it]}, expected {' or '.join(IMAGE_TYPES)} (--image-topic)")
    infos = sorted(t for t, ty in topics.items() if ty == CAMERA_INFO)
    ct = cam.info_topic
    if ct is not None:
        if topics.get(ct) != CAMERA_INFO:
            raise RobocalError(f"{at(path, ct)}: {'is ' + topics[ct] if ct in topics else 'not in the bag'}; "
                               f"CameraInfo topics: {', '.join(infos) or 'none'} (--camera-info-topic)")
        return it, ct
    ns = it.rstrip("/").rsplit("/", 1)[0]
    beside = [t for t in infos if t.rsplit("/", 1)[0] in (ns, ns.rsplit("/", 1)[0])]
    if len(beside) == 1:
        return it, beside[0]
    return it, infos[0] if len(infos) == 1 else None


def _info(path: Path, topic: str, msgs: list[tuple[int, bytes]], warnings: list[str]):
    """The first CameraInfo's `CameraInfo`; a later one with another size or K is a warning."""
    decoded = []
    for i, (_, data) in enumerate(msgs):
        try:
            decoded.append(camera_info(typestore().deserialize_cdr(data, CAMERA_INFO)))
        except Exception as e:  # noqa: BLE001 — the library's errors are the data's
            raise RobocalError(f"{at(path, topic, i)}: CDR does not decode as {CAMERA_INFO} "
                               f"({type(e).__name__}: {e})") from None
    first = decoded[0]
    for i, d in enumerate(decoded[1:], 1):
        if d.size != first.size or (d.k is None) != (first.k is None) or (d.k is not None and not np.allclose(d.k, first.k)):
            warnings.append(f"{at(path, topic, i)}: CameraInfo differs from record 0 (size or K/D); record 0 is used")
            break
    return first


def clock_offsets(tj_s: np.ndarray, q: np.ndarray, tm_s: np.ndarray, paired: np.ndarray, window_s: float,
                  max_speed: float, reach_s: float, step_s: float = 0.01) -> dict:
    """What the stillness says of the camera clock's offset δ (camera − joints, s; module
    docstring): over δ in [−reach, reach] (step `step_s`), the `paired` images still at t − δ.
    Returns ``consistent_s``, the range of δ around 0 where every paired image is still, and
    ``estimate_s``, its middle (the offset when the images were taken mid-stop; None where the range
    reaches the grid's end)."""
    d = np.round(np.arange(-reach_s, reach_s + step_s / 2, step_s), 9)
    out: dict = {"grid_s": [float(d[0]), float(d[-1]), step_s], "consistent_s": None, "estimate_s": None}
    if not paired.any():
        return out
    p = standstill.pair(tj_s, q, (tm_s[paired][None, :] - d[:, None]).ravel(), window_s, max_speed)
    ok = p.still.reshape(len(d), int(paired.sum())).all(1)
    idx = np.flatnonzero(ok)
    centre = int(np.argmin(np.abs(d)))
    runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1) if len(idx) else []
    r = next((r for r in runs if r[0] <= centre <= r[-1]), None)
    if r is not None:
        out["consistent_s"] = [float(d[r[0]]), float(d[r[-1]])]
        if r[0] > 0 and r[-1] < len(d) - 1:
            out["estimate_s"] = round(float(d[r[0]] + d[r[-1]]) / 2, 6)
    return out


def _detect_message(args) -> Detection:
    """Decode one image message and find the target in it (a worker process's task)."""
    typename, data, name, target, max_edge_px, size = args
    import cv2

    cv2.setNumThreads(1)
    img, status, reason = decode_image(typename, data, size)
    if img is None:
        return Detection(name, status, reason, size or (0, 0))
    return detect_array(img, name, target, max_edge_px)


def _detect(bag, topic: str, typename: str, wanted: dict[int, str], cam: CameraSpec, size, progress):
    """Second pass over the open `bag` (`pipeline.ros2.bag.Bag`): the `wanted` records (index → name) of the
    image topic, each decoded once and searched for the target in a process pool with a bounded number of
    images in flight."""
    workers = cam.workers or min(os.cpu_count() or 1, max(1, len(wanted) // 4))
    out: dict[int, Detection] = {}
    bodies = (data for _, _, data in bag.messages([topic]))
    jobs = ((i, (typename, bytes(data), wanted[i], cam.target, cam.max_edge_px, size))
            for i, data in enumerate(bodies) if i in wanted)
    if workers <= 1:
        for i, job in jobs:
            out[i] = _detect_message(job)
            if progress:
                progress(len(out), len(wanted))
    else:
        from concurrent.futures.process import BrokenProcessPool

        try:
            _pooled(jobs, workers, wanted, out, progress)
        except BrokenProcessPool as e:
            raise RobocalError(f"{at(bag.path, topic)}: a detection process died ({e}); --workers 1 detects in this "
                               "process") from None
    return out


def _pooled(jobs, workers: int, wanted: dict, out: dict, progress) -> None:
    """`_detect_message` over `jobs` ((record, args), …) in a pool, at most 4 per worker in flight."""
    with pool(workers) as ex:
        pending: list = []

        def collect() -> None:
            j, f = pending.pop(0)
            out[j] = f.result()
            if progress:
                progress(len(out), len(wanted))

        for i, job in jobs:
            pending.append((i, ex.submit(_detect_message, job)))
            while len(pending) >= 4 * workers or (pending and pending[0][1].done()):
                collect()
        while pending:
            collect()


def read_camera_bag(bag, joints: list[str], spec: BagSpec, cam: CameraSpec, progress=None,
                    on_paired=None):
    """(detections (each paired image, `q` its joint positions and `t_ns` its stamp attached),
    campaign extras, the problems that make the bag bad input (one line each; empty if none), the
    `CameraInfo` or None).  `on_paired(extras)` sees the pairing before the detection starts.
    Bad images (unreadable, unsupported encoding, wrong size) are among the detections with their
    status; the caller decides (`skip_bad`).  `bag`: an open `pipeline.ros2.bag.Bag`."""
    path = bag.path
    if spec.time not in ("header", "log"):
        raise RobocalError(f"--time {spec.time!r}: expected header or log")
    if cam.clock_bound_s < 0:
        raise RobocalError(f"--clock-offset-bound-s {cam.clock_bound_s}: must be 0 or more (s)")
    def one_pass(b):
        topics = b.topics
        jt = choose_joint_topic(path, topics, spec.joint_topic)
        it, ct = choose_camera_topics(path, topics, cam)
        side = _Stamps(it)
        wanted = [jt, it] + ([ct] if ct else [])
        got = read_joint_states(path, jt, split(b.messages(wanted), jt, side, several=True), joints)
        return topics, jt, it, ct, side, got

    topics, jt, it, ct, side, (js, jlog, Q, jreport, _) = bag.read(one_pass)
    warnings: list[str] = list(bag.warnings)
    if not side.stamp:
        raise RobocalError(f"{at(path, it)}: no messages")
    problems: list[str] = []
    info = None
    if ct is None:
        problems.append(f"{at(path, it)}: no {CAMERA_INFO} topic in the bag for it (the image size and the starting "
                        "intrinsics come from CameraInfo; --camera-info-topic names one)")
    elif not side.info:
        problems.append(f"{at(path, ct)}: no CameraInfo messages (the image size and the starting intrinsics of "
                        f"{it} come from it)")
    else:
        info = _info(path, ct, side.info, warnings)
    stamps = np.asarray(side.stamp, np.int64)
    tm, msrc = _times(np.where(stamps < 0, 0, stamps), side.log, spec.time == "header")
    tm = tm - int(round(cam.clock_offset_s * 1e9))
    tj, jsrc = _times(js, jlog, spec.time == "header")
    if jsrc != msrc:
        warnings.append(f"{path}: joint states timed by {jsrc}, images by {msrc} (a topic without header stamps)")
    order = np.argsort(tj, kind="stable")
    tj, Q = tj[order], Q[order]
    t0 = int(min(tj[0], tm.min()))
    tj_s, tm_s = (tj - t0) * 1e-9, (tm - t0) * 1e-9
    wide = spec.window_s + 2 * cam.clock_bound_s
    pairing = standstill.pair(tj_s, Q, tm_s, wide, spec.max_speed * spec.window_s / wide)
    summ = standstill.summary(pairing, tm_s, joints)
    summ["clock_offset_bound_s"] = cam.clock_bound_s
    summ["standstill_window_s"] = spec.window_s
    clock = clock_offsets(tj_s, Q, tm_s, pairing.still, spec.window_s, spec.max_speed,
                          reach_s=max(3.0, 4 * cam.clock_bound_s))
    clock |= {"bound_s": cam.clock_bound_s, "applied_offset_s": cam.clock_offset_s,
              "rule": "an image is paired only where the robot stood still for ±bound around its stamp "
                      "(the standstill window widened by 2·bound, the same peak-to-peak motion allowed)"}
    keep = np.flatnonzero(pairing.still)
    extras = {
        "source_files": [str(path)],
        "ros2": {"joint_topic": jt, "image_topic": it, "image_type": topics[it], "camera_info_topic": ct,
                 "time_joint_states": jsrc, "time_images": msrc, "t0_ns": t0, "joint_states": jreport,
                 "pairing": summ, "clock_offset": clock, "image_records": [int(i) for i in keep]},
    }
    if info is not None and info.k is None:
        warnings.append(f"{at(path, ct)}: CameraInfo K is all zero (an uncalibrated camera): the calibration "
                        "starts from OpenCV's calibrateCamera alone")
    if warnings:
        extras["import_warnings"] = warnings
    if bag.data_lost:
        extras["data_lost"] = bag.data_lost  # the bag's damage: ingest's status is then warn, never pass
    if on_paired is not None:
        on_paired(extras)
    names = {int(i): f"{it}#{i}" for i in keep}
    size = info.size if info is not None else None
    dets = _detect(bag, it, topics[it], names, cam, size, progress)
    out = []
    for i in keep:
        d = dets[int(i)]
        d.q, d.t_ns, d.record = pairing.q[i], int(tm[i]), int(i)  # type: ignore[attr-defined]
        out.append(d)
    for d in out:
        if d.status in BAD:
            problems.append(f"{at(path, it, d.record)}: {d.status}: {d.reason}")  # type: ignore[attr-defined]
    if info is not None:
        extras["camera_info"] = {"width": info.width, "height": info.height,
                                 "distortion_model": info.distortion_model,
                                 "k": None if info.k is None else [float(v) for v in info.k]}
    return out, extras, problems, info
