"""Find a calibration target's corners in images (OpenCV), one `Detection` per image.

Chessboards: `cv2.findChessboardCorners` (adaptive threshold, normalised) then `cv2.cornerSubPix` (11×11 window), the edge
sharpness by `cv2.estimateChessboardSharpness`; ChArUco: `cv2.aruco.CharucoDetector`; AprilGrid
(ArUco grid): `cv2.aruco.ArucoDetector` with sub-pixel corner refinement.

Every image gets a status; only ``ok`` and ``partial`` images carry corners a calibration uses,
and each image that is not used is listed with its reason:

* ``unreadable`` — the file is not an image OpenCV decodes;
* ``too large`` — its header states more than `MAX_PIXELS` pixels (judged before decoding: a
  hostile 30000×30000 PNG is not decoded into gigabytes);
* ``wrong size`` — its size differs from the first readable image's (from the headers where
  Pillow reads them, so a wrong-size image is not decoded either);
* ``not found`` — the target is not in it (or too little of it: fewer than `MIN_CORNERS`);
* ``blurred`` — the chessboard's mean edge width exceeds `max_edge_px`;
* ``partial`` — a ChArUco / grid seen in part (used: its corner ids say which corners they are).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.camera.targets import Target, parse

MIN_CORNERS = 6
MAX_PIXELS = 250_000_000  # width × height: above every calibration camera (the largest sensors sold: ≈ 150 MP)
MAX_EDGE_PX = 5.0  # a chessboard whose black-white edges are wider than this (px, 10 %–90 %) is blurred
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")
USED = ("ok", "partial")


@dataclass
class Detection:
    """One image's result: corner ids (m,) and pixels (m,2) px (u right, v down, pixel centres at
    integers), its size (width, height) px, status and reason (module docstring)."""

    name: str
    status: str
    reason: str = ""
    size: tuple[int, int] = (0, 0)
    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    pixels: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    sharpness_px: float = float("nan")

    @property
    def used(self) -> bool:
        return self.status in USED


def image_files(folder: Path) -> list[Path]:
    """The image files of a folder (by suffix), sorted by name."""
    return sorted(p for p in Path(folder).iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)


def header_size(path) -> tuple[int, int] | None:
    """(width, height) px from the header of an image file (a path, or a binary file object), without
    decoding its pixels (Pillow reads PNG, JPEG, BMP, TIFF, WebP, PGM/PPM headers lazily); None where
    Pillow cannot read the header."""
    from PIL import Image

    limit, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None  # only the header is read: `too_large` judges it
    try:
        with Image.open(path) as im:
            return int(im.size[0]), int(im.size[1])
    except Exception:  # noqa: BLE001 — any header Pillow cannot parse: OpenCV decides when it decodes
        return None
    finally:
        Image.MAX_IMAGE_PIXELS = limit


def too_large(size: tuple[int, int] | None) -> str | None:
    """The reason an image of `size` (w, h) px is refused before decoding, or None."""
    if size is not None and size[0] * size[1] > MAX_PIXELS:
        return (f"{size[0]}x{size[1]} px ({size[0] * size[1] / 1e6:.0f} MP) in its header, more than robocal "
                f"decodes ({MAX_PIXELS / 1e6:.0f} MP)")
    return None


def subpix_window(px: np.ndarray, target: Target) -> int:
    """cornerSubPix's half window (px): 11, or less where the board's corners are closer than
    2.5 half windows (a window spanning a whole square would pull a corner onto its neighbour)."""
    g = px.reshape(target.rows, target.cols, 2)
    d = min(np.linalg.norm(np.diff(g, axis=0), axis=2).min(), np.linalg.norm(np.diff(g, axis=1), axis=2).min())
    return int(np.clip(d / 2.5, 2, 11))


def _chessboard(img: np.ndarray, target: Target, max_edge_px: float) -> tuple:
    import cv2

    # no CALIB_CB_FAST_CHECK: a calibration image shows the board, and the check's own pass doubled the
    # time on the images where the first threshold did not already find it (0.11 → 0.05 s a 640×480 image)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, c = cv2.findChessboardCorners(img, target.pattern_size, flags=flags)
    if not ok:
        return "not found", f"no {target.cols}x{target.rows}-corner chessboard found", None, None, np.nan
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    c = cv2.cornerSubPix(img, c, (subpix_window(c.reshape(-1, 2), target),) * 2, (-1, -1), crit)
    sharp = float(cv2.estimateChessboardSharpness(img, target.pattern_size, c)[0][0])
    ids = np.arange(target.n_corners)
    if sharp > max_edge_px:
        return "blurred", f"edges {sharp:.1f} px wide (> {max_edge_px:g} px)", ids, c.reshape(-1, 2), sharp
    return "ok", "", ids, c.reshape(-1, 2), sharp


def _charuco(img: np.ndarray, target: Target) -> tuple:
    import cv2

    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    det = cv2.aruco.CharucoDetector(target.board, cv2.aruco.CharucoParameters(), params)
    corners, ids, _, _ = det.detectBoard(img)
    return _partial(target, ids, corners, "ChArUco corners")


def _grid(img: np.ndarray, target: Target) -> tuple:
    import cv2

    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    det = cv2.aruco.ArucoDetector(target.aruco_dictionary(), params)
    corners, ids, _ = det.detectMarkers(img)
    if ids is None:
        return _partial(target, None, None, "tag corners")
    ids = ids.ravel()
    keep = ids < target.cols * target.rows  # a tag of the dictionary that is not on this board
    cid = (4 * ids[keep, None] + np.arange(4)).ravel()
    px = np.asarray(corners, float)[keep].reshape(-1, 2)
    return _partial(target, cid, px, "tag corners")


def _partial(target: Target, ids, px, what: str) -> tuple:
    if ids is None or len(ids) < MIN_CORNERS:
        m = 0 if ids is None else len(ids)
        return "not found", f"{m} {what} found (fewer than {MIN_CORNERS})", None, None, np.nan
    ids = np.asarray(ids).ravel().astype(np.int64)
    order = np.argsort(ids, kind="stable")
    ids, px = ids[order], np.asarray(px, float).reshape(-1, 2)[order]
    if len(ids) < target.n_corners:
        return "partial", f"{len(ids)} of {target.n_corners} {what}", ids, px, np.nan
    return "ok", "", ids, px, np.nan


def detect_image(path: str | Path, target: Target | str, max_edge_px: float = MAX_EDGE_PX,
                 size: tuple[int, int] | None = None) -> Detection:
    """Detect `target` in the image file `path` (grey levels; colour images are converted)."""
    import cv2

    cv2.setNumThreads(1)
    path = Path(path)
    head = header_size(path)
    if (why := too_large(head)) is not None:
        return Detection(path.name, "too large", why, head)
    if size is not None and head is not None and head != tuple(size):
        return Detection(path.name, "wrong size", f"{head[0]}x{head[1]} px, the others are {size[0]}x{size[1]} px",
                         head)
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        return Detection(path.name, "unreadable", "not an image OpenCV can decode (damaged or unknown format)")
    return detect_array(img, path.name, target, max_edge_px, size)


def detect_array(img: np.ndarray, name: str, target: Target | str, max_edge_px: float = MAX_EDGE_PX,
                 size: tuple[int, int] | None = None) -> Detection:
    """Detect `target` in a decoded 8-bit grey image (height, width) called `name`; `size`
    (width, height) px: the size every image must have (else status ``wrong size``)."""
    target = parse(target) if isinstance(target, str) else target
    wh = (int(img.shape[1]), int(img.shape[0]))
    if size is not None and wh != tuple(size):
        return Detection(name, "wrong size", f"{wh[0]}x{wh[1]} px, the others are {size[0]}x{size[1]} px", wh)
    if target.kind == "chessboard":
        status, reason, ids, px, sharp = _chessboard(img, target, max_edge_px)
    elif target.kind == "charuco":
        status, reason, ids, px, sharp = _charuco(img, target)
    else:
        status, reason, ids, px, sharp = _grid(img, target)
    if ids is None:
        return Detection(name, status, reason, wh)
    return Detection(name, status, reason, wh, np.asarray(ids, np.int64), np.asarray(px, float), sharp)


@contextmanager
def pool(workers: int) -> Iterator[ProcessPoolExecutor]:
    """A process pool for detection whose workers are forked from a forkserver, not from this process:
    a process that has run OpenCV's own thread pool (rendering, resizing) deadlocks the children it
    forks in their first OpenCV call.  A forkserver this pool had to start is stopped with the pool, so
    that nothing else in the process (a local cluster's workers) is later forked from it."""
    import multiprocessing

    from pipeline import forkserver

    fresh = not forkserver.running()
    try:
        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("forkserver")) as ex:
            yield ex
    finally:
        if fresh:
            forkserver.terminate()


def _one(args) -> Detection:
    return detect_image(*args)


def detect_folder(files: list[Path], target: Target, max_edge_px: float = MAX_EDGE_PX,
                  workers: int | None = None, progress=None) -> list[Detection]:
    """`detect_image` over `files` (in order) with a process pool of `workers` (default: the CPU
    count, 1 for a handful of images); the image size is the first readable image's.  `progress`
    (optional) is called with (done, total)."""
    import cv2

    size = None
    for f in files:  # the reference size: the first image's header (else the first image OpenCV decodes)
        head = header_size(f)
        if too_large(head) is not None:
            continue
        if head is not None:
            size = head
            break
        img = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
        if img is not None:
            size = (int(img.shape[1]), int(img.shape[0]))
            break
    jobs = [(f, target.spec, max_edge_px, size) for f in files]
    workers = workers or min(os.cpu_count() or 1, max(1, len(files) // 4))
    out: list[Detection] = []
    if workers <= 1:
        for i, j in enumerate(jobs):
            out.append(_one(j))
            if progress:
                progress(i + 1, len(jobs))
        return out
    with pool(workers) as ex:
        for i, d in enumerate(ex.map(_one, jobs, chunksize=max(1, len(jobs) // (8 * workers)))):
            out.append(d)
            if progress:
                progress(i + 1, len(jobs))
    return out
