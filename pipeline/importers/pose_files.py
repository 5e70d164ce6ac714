"""The robot's state at each calibration image, read from the files hand-eye campaigns ship
(`robocal import images --poses / --joints`).

* **Pose CSV** (``--poses``): a header with ``image``, ``x, y, z`` (m) and either ``qx, qy, qz, qw``
  or ``roll, pitch, yaw`` (rad, URDF rpy: R = Rz(yaw)·Ry(pitch)·Rx(roll)) — the flange in the robot
  base frame at each image, which is matched by file name or stem.
* **Pose matrices** (``--poses``, a file whose first line is numbers): one homogeneous matrix
  T_base_flange per line, row-major, 16 numbers (or its top three rows, 12), separated by blanks,
  tabs or commas; ``#`` starts a comment.  Line N (counting only the lines that hold a matrix) goes
  with the image whose file name ends in the number N (``im_01.bmp``, ``img7.png``, ``0012.jpg``):
  1-based, as RWHE-Calib's ``RobotPosesVec.txt`` numbers them, or 0-based when an image is numbered 0.
* **Joint CSV** (``--joints``): ``image`` and one column per joint of the chain (rad or deg, m).

A pose becomes the joint positions (x, y, z, yaw, pitch, roll) of the six-joint pose chain
(`pipeline.importers.images.pose_chain`).  Refused with one line naming the file and the row (line) and
column: a field that is not a number, an empty field or NaN, a value beyond ±`bounds.BOUND` (the bound
of every importer), a joint reading far outside its URDF limits (`bounds.check_joints`), a position beyond 100 m (mm given as m), an angle beyond ±2π (degrees
given as radians), both a quaternion and roll/pitch/yaw, a quaternion that is not a unit one, a
matrix whose rotation is not orthonormal or whose last row is not 0 0 0 1, and one image given two
different states (by name or stem).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.errors import RobocalError
from pipeline.importers import bounds, csv_text

MAX_POSITION_M = 100.0
ROTATION_TOL = 1e-3  # max |RᵀR − I| of a pose matrix's rotation
QUAT_TOL = 1e-3
_TRAILING_NUMBER = re.compile(r"(\d+)\D*$")


@dataclass
class States:
    """Image → robot state (joint positions of the chain, SI): by file name / stem (CSV), or by the
    number an image's name ends in (pose matrices, `base` the number of the first line)."""

    path: Path
    by_name: dict[str, np.ndarray] = field(default_factory=dict)
    by_number: dict[int, np.ndarray] | None = None
    base: int = 1

    def bind(self, names: list[str]) -> None:
        """Fix the numbering of the matrix lines from the images' names (0-based if one is numbered 0)."""
        if self.by_number is not None:
            nums = [number_of(n) for n in names]
            self.base = 0 if 0 in nums else 1

    def lookup(self, name: str) -> np.ndarray | None:
        if self.by_number is not None:
            k = number_of(name)
            return None if k is None else self.by_number.get(k - self.base + 1)
        return self.by_name.get(name, self.by_name.get(Path(name).stem))

    def missing(self, name: str) -> str:
        """Why `name` has no state (for the image's listed reason)."""
        if self.by_number is None:
            return f"no row for it in {self.path.name}"
        k = number_of(name)
        if k is None:
            return f"its name holds no number, so no line of {self.path.name} goes with it"
        return (f"numbered {k}, but {self.path.name} holds {len(self.by_number)} pose line(s) "
                f"(line N ↔ image numbered {'N − 1' if self.base == 0 else 'N'})")

    def rule(self) -> str:
        """How images were paired with the file's rows (for the import's message)."""
        if self.by_number is None:
            return f"{self.path.name}: rows by image name"
        return (f"{self.path.name}: {len(self.by_number)} pose matrices, line N ↔ the image numbered "
                f"{'N − 1 (0-based)' if self.base == 0 else 'N (1-based)'}")


def number_of(name: str) -> int | None:
    """The number an image's file name (stem) ends in, or None."""
    m = _TRAILING_NUMBER.search(Path(name).stem)
    return int(m.group(1)) if m else None


def _table(path: Path, need: list[str]) -> tuple[list[str], dict[str, list[str]], int]:
    header, cols, n = csv_text.read_columns(path)
    if "image" not in cols:
        raise RobocalError(f"{path}: no 'image' column (the image file name of each row)")
    missing = [c for c in need if c not in cols]
    if missing:
        raise RobocalError(f"{path}: column(s) {', '.join(missing)} missing (have: {', '.join(header)})")
    return header, cols, n


def _numbers(path: Path, cols: dict[str, list[str]], names: list[str]) -> np.ndarray:
    out = np.empty((len(cols["image"]), len(names)))
    for j, c in enumerate(names):
        v = csv_text.numbers(path, c, cols[c])
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            text = cols[c][bad[0]].strip()
            raise RobocalError(f"{path}: row {bad[0] + 2}: column {c!r} is "
                               + (f"{text!r}: not a finite number" if text else "empty"))
        bounds.check_bound(path, c, v)
        out[:, j] = v
    return out


def _by_name(path: Path, images: list[str], q: np.ndarray, what: str) -> dict[str, np.ndarray]:
    """Image name → row, refusing one image (by name or stem) given two different states."""
    out: dict[str, np.ndarray] = {}
    row_of: dict[str, int] = {}
    for i, name in enumerate(images):
        name = name.strip()
        if not name:
            raise RobocalError(f"{path}: row {i + 2}: column 'image' is empty")
        for key in dict.fromkeys((name, Path(name).stem)):
            j = row_of.get(key)
            if j is not None and not np.array_equal(q[j], q[i]):
                raise RobocalError(f"{path}: rows {j + 2} and {i + 2} give image {key!r} two different {what}s "
                                   "(one state per image)")
            row_of.setdefault(key, i)
        out.setdefault(name, q[i])
    for key, i in row_of.items():  # the stem finds the row too (im_01 ↔ im_01.bmp)
        out.setdefault(key, q[i])
    return out


def _check_positions(path: Path, xyz: np.ndarray, row0: int, what: str = "row") -> None:
    far = np.flatnonzero(np.any(np.abs(xyz) > MAX_POSITION_M, axis=1))
    if far.size:
        i = int(far[0])
        raise RobocalError(f"{path}: {what} {i + row0}: position {xyz[i].tolist()} beyond {MAX_POSITION_M:g} m "
                           "(mm given as m? robocal reads metres)")


def read_pose_csv(path: Path) -> States:
    """A pose CSV (module docstring) → States of the pose chain's joint positions."""
    header, cols, _ = _table(path, ["x", "y", "z"])
    quat = [c for c in ("qx", "qy", "qz", "qw") if c in cols]
    rpy = [c for c in ("roll", "pitch", "yaw") if c in cols]
    if quat and rpy:
        raise RobocalError(f"{path}: columns {', '.join(quat)} and {', '.join(rpy)}: give the orientation once, "
                           "as a quaternion (qx, qy, qz, qw) or as roll, pitch, yaw (rad)")
    if not quat and not rpy:
        raise RobocalError(f"{path}: no orientation: columns qx, qy, qz, qw or roll, pitch, yaw (rad) missing "
                           f"(have: {', '.join(header)})")
    xyz = _numbers(path, cols, ["x", "y", "z"])
    _check_positions(path, xyz, 2)
    if quat:
        if len(quat) < 4:
            raise RobocalError(f"{path}: column(s) {', '.join(c for c in ('qx', 'qy', 'qz', 'qw') if c not in cols)} "
                               "missing (a quaternion is qx, qy, qz, qw)")
        q = _numbers(path, cols, ["qx", "qy", "qz", "qw"])
        norm = np.linalg.norm(q, axis=1)
        bad = np.flatnonzero(np.abs(norm - 1) > QUAT_TOL)
        if bad.size:
            raise RobocalError(f"{path}: row {bad[0] + 2}: qx..qw is not a unit quaternion (norm {norm[bad[0]]:.4g})")
        ypr = Rotation.from_quat(q / norm[:, None]).as_euler("ZYX")
    else:
        if len(rpy) < 3:
            raise RobocalError(f"{path}: column(s) {', '.join(c for c in ('roll', 'pitch', 'yaw') if c not in cols)} "
                               "missing (roll, pitch, yaw in rad)")
        a = _numbers(path, cols, ["roll", "pitch", "yaw"])
        big = np.argwhere(np.abs(a) > 2 * np.pi)
        if big.size:
            i, j = big[0]
            raise RobocalError(f"{path}: row {i + 2}: column {('roll', 'pitch', 'yaw')[j]!r} is {a[i, j]:.6g}, beyond "
                               "±2π: degrees given as radians? (robocal reads roll, pitch, yaw in rad)")
        ypr = a[:, ::-1]
    return States(path, _by_name(path, cols["image"], np.hstack([xyz, ypr]), "pose"))


def read_pose_matrices(path: Path) -> States:
    """Pose matrices, one per line (module docstring) → States numbered by line."""
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise RobocalError(f"{path}: byte {e.start}: not UTF-8 text (a pose file is text)") from None
    rows, lines = [], []
    for ln, raw in enumerate(text.splitlines(), 1):
        body = raw.split("#", 1)[0].replace(",", " ").split()
        if not body:
            continue
        if len(body) not in (12, 16):
            raise RobocalError(f"{path}: line {ln}: {len(body)} numbers; a pose line holds a row-major 4×4 matrix "
                               "(16 numbers) or its top three rows (12)")
        v = csv_text.numbers(path, "", body, where=lambda i, ln=ln: f"line {ln}, number {i + 1}")
        if not np.all(np.isfinite(v)):
            raise RobocalError(f"{path}: line {ln}: number {int(np.flatnonzero(~np.isfinite(v))[0]) + 1} is NaN or inf")
        rows.append(np.r_[v, [0.0, 0.0, 0.0, 1.0]][:16].reshape(4, 4) if len(v) == 12 else v.reshape(4, 4))
        lines.append(ln)
    if not rows:
        raise RobocalError(f"{path}: no pose lines (one row-major 4×4 base→flange matrix per line)")
    T = np.stack(rows)
    for k, (Tk, ln) in enumerate(zip(T, lines)):
        if np.max(np.abs(Tk[3] - [0, 0, 0, 1])) > 1e-6:
            raise RobocalError(f"{path}: line {ln}: last row {Tk[3].tolist()} is not 0 0 0 1 (a homogeneous matrix, "
                               "row-major)")
        R = Tk[:3, :3]
        err = float(np.max(np.abs(R.T @ R - np.eye(3))))
        if err > ROTATION_TOL or np.linalg.det(R) < 0:
            raise RobocalError(f"{path}: line {ln}: the rotation part is not a rotation (max |RᵀR − I| {err:.3g}, "
                               f"det {np.linalg.det(R):.4g}); is the matrix row-major, in m?")
        _check_positions(path, Tk[None, :3, 3], ln, "line")
    ypr = Rotation.from_matrix(T[:, :3, :3]).as_euler("ZYX")
    q = np.hstack([T[:, :3, 3], ypr])
    return States(path, by_number={k + 1: q[k] for k in range(len(q))})


def read_poses(path: Path) -> States:
    """A pose file: matrices when its first line holds numbers, else a pose CSV (module docstring)."""
    path = Path(path)
    try:
        head = path.read_bytes()[:4096].decode("utf-8-sig", errors="replace")
    except FileNotFoundError:
        raise RobocalError(f"{path}: no such file") from None
    except OSError as e:
        raise RobocalError(f"{path}: cannot read ({type(e).__name__}: {e})") from None
    first = next((ln.split("#", 1)[0] for ln in head.splitlines() if ln.split("#", 1)[0].strip()), "")
    fields = first.replace(",", " ").split()
    if fields and all(csv_text.is_number(f) for f in fields):
        return read_pose_matrices(path)
    return read_pose_csv(path)


def read_joints(path: Path, desc, joint_units: str = "rad") -> States:
    """A joint CSV (module docstring) → States of the chain `desc`'s joint positions (rad, m)."""
    path, names = Path(path), list(desc.joint_names)
    _, cols, _ = _table(path, names)
    q = _numbers(path, cols, names)
    revolute = np.array([j.type != "prismatic" for j in desc.movable])
    if joint_units == "deg":
        q[:, revolute] = np.deg2rad(q[:, revolute])
    lo = np.array([j.lower for j in desc.movable], float)
    hi = np.array([j.upper for j in desc.movable], float)
    bounds.check_joints(q, names, lo, hi, revolute, lambda i, k: f"{path}: row {i + 2}: column {names[k]!r}",
                        "" if joint_units == "deg" else "use --joint-units deg")
    return States(path, _by_name(path, cols["image"], q, "joint state"))
