"""Errors of a joint's reading as terms of the calibrated model: the true angle is the reading plus δq.

Four families (parameters of `pipeline.measurements.tree_point.TreePointModel`), on the read joints
of a `UrdfTree` (`UrdfTree.joint_names`; a coupled joint follows the corrected readings of its
drivers), q the joint's reading in rad:

* ``encoder-eccentricity``: δq = a·sin q + b·cos q (``J.ecc_sin`` a, ``J.ecc_cos`` b, rad) — an
  encoder disc mounted off its axis, once per turn;
* ``joint-scale``: δq = s·q (``J.scale`` s, rad/rad) — a gear ratio or encoder resolution off by s;
* ``joint-coupling``: δq_j = κ·q_i (``J.coupling`` κ, rad/rad), i the read joint before j on its
  chain (`driver`) — a transmission through the previous joint (cables, belts, a parallelogram);
* ``backlash``: δq = b·d/2 (``J.backlash`` b, rad: the free play), d = ±1 the joint's direction of
  approach at the measurement (the sign of its last motion before the standstill; the table's column
  ``approach`` (n, n_joints), from the CSV columns ``dir_<joint>`` or the recording's ``approach``
  field, else derived from the joint stream before each measurement — a ROS 2 bag's JointState at
  import, a recording's encoder stream at load (`pipeline.systems.urdf_robot.approach_from_stream`);
  0 unknown: no correction).  Offered only for a read joint approached from both sides
  (at least `MIN_SIDE` rows each); b is fitted free of sign — a play is b ≥ 0, a negative estimate
  beyond its σ says the reading leads rather than lags.  Unlike the other three families (offered
  after the geometry), backlash is offered to the model selection with the geometric groups
  (`TreePointModel.late_groups`).  Without directions it is not fitted:
  `BACKLASH_ABSENT` says so in the sidecar and the report.

Identifiability: a joint whose readings spread less than `MIN_SPREAD_RAD` (RMS about their mean) is
not offered a term (its sin, cos and q columns are then the joint offset's); the rank test of
identification holds any term the data still cannot tell apart, and the held-out model selection
keeps a family only when it lowers the held-out error.
"""

from __future__ import annotations

import numpy as np

FAMILIES = ("encoder-eccentricity", "joint-scale", "joint-coupling", "backlash")
KINDS = {"ecc_sin": "encoder-eccentricity", "ecc_cos": "encoder-eccentricity", "scale": "joint-scale",
         "coupling": "joint-coupling", "backlash": "backlash"}
GROUPS = {"encoder-eccentricity": "encoder eccentricity", "joint-scale": "joint scale",
          "joint-coupling": "joint coupling", "backlash": "backlash"}
UNITS = {"ecc_sin": "rad", "ecc_cos": "rad", "scale": "rad/rad", "coupling": "rad/rad", "backlash": "rad"}
SUFFIXES = tuple(f".{k}" for k in KINDS)
MIN_SPREAD_RAD = 0.1
MIN_SIDE = 5
BACKLASH_ABSENT = ("backlash not fitted: the recording carries no direction of motion at the measurements "
                   "(postures only: no dir_<joint> columns, no approach field, no joint stream moving before them)")


def is_encoder(name: str) -> bool:
    """Whether a parameter name is one of this module's terms."""
    return name.endswith(SUFFIXES)


def family(name: str) -> str:
    return KINDS[name.rsplit(".", 1)[1]]


def driver(tree, joint: str) -> str | None:
    """The read joint before `joint` on its chain root → tip (None for the first read joint)."""
    read = set(tree.joint_names)
    for d in tree.descs:
        names = [j.name for j in d.movable]
        if joint in names:
            before = [n for n in names[: names.index(joint)] if n in read]
            return before[-1] if before else None
    return None


def candidates(tree, q: np.ndarray, families: tuple[str, ...], approach: np.ndarray | None = None) -> tuple[str, ...]:
    """Parameter names of the `families` terms the readings q (n, n_joints) and the directions of approach
    (n, n_joints, −1/0/+1; None: unknown) can carry (module docstring)."""
    q = np.atleast_2d(np.asarray(q, float))
    by = {j.name: j for j in tree.all_joints}
    spread = np.sqrt(np.mean((q - q.mean(0)) ** 2, axis=0)) if len(q) else np.zeros(q.shape[1])
    moves = {n: bool(spread[i] >= MIN_SPREAD_RAD) for i, n in enumerate(tree.joint_names)}
    out = []
    for n in tree.joint_names:
        revolute = by[n].type in ("revolute", "continuous")
        if not moves[n] or not revolute:
            continue
        if "encoder-eccentricity" in families:
            out += [f"{n}.ecc_sin", f"{n}.ecc_cos"]
        if "joint-scale" in families:
            out.append(f"{n}.scale")
        d = driver(tree, n)
        if "joint-coupling" in families and d is not None and moves[d]:
            out.append(f"{n}.coupling")
    if "backlash" in families and approach is not None and len(q):
        a = np.asarray(approach)
        for i, n in enumerate(tree.joint_names):
            if by[n].type in ("revolute", "continuous") and min(np.sum(a[:, i] > 0), np.sum(a[:, i] < 0)) >= MIN_SIDE:
                out.append(f"{n}.backlash")
    order = {f: i for i, f in enumerate(FAMILIES)}
    return tuple(sorted(out, key=lambda s: order[family(s)]))  # one family after the other (stable)


_PLANS: dict = {}


def _plan(tree, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(read-joint column of each term, the column its basis reads, kind code 0 sin 1 cos 2 q 3 d/2), cached."""
    key = (id(tree.descs), tree.coupled, names)
    hit = _PLANS.get(key)
    if hit is not None and hit[0] is tree.descs:
        return hit[1]
    col = {n: i for i, n in enumerate(tree.joint_names)}
    cols, src, code = [], [], []
    for name in names:
        joint, kind = name.rsplit(".", 1)
        cols.append(col[joint])
        src.append(col[driver(tree, joint)] if kind == "coupling" else col[joint])
        code.append({"ecc_sin": 0, "ecc_cos": 1, "backlash": 3}.get(kind, 2))
    plan = (np.array(cols, int), np.array(src, int), np.array(code, int))
    if len(_PLANS) > 64:
        _PLANS.clear()
    _PLANS[key] = (tree.descs, plan)
    return plan


def basis(tree, names: tuple[str, ...], q: np.ndarray, approach: np.ndarray | None = None
          ) -> tuple[np.ndarray, np.ndarray]:
    """(B (n, T), col (T,)): term t adds x_t · B[:, t] to read joint col[t] (rad per unit parameter);
    `approach` (n, n_joints) −1/0/+1 the directions of approach (None: unknown, backlash adds nothing)."""
    q = np.atleast_2d(np.asarray(q, float))
    cols, src, code = _plan(tree, tuple(names))
    v = q[:, src]
    d = np.zeros_like(v) if approach is None else np.atleast_2d(np.asarray(approach, float))[:, src]
    B = np.where(code == 0, np.sin(v), np.where(code == 1, np.cos(v), np.where(code == 3, 0.5 * d, v)))
    return B, cols


def corrected(tree, names: tuple[str, ...], x: np.ndarray, q: np.ndarray,
              approach: np.ndarray | None = None) -> np.ndarray:
    """The readings q (n, n_joints) with the terms `names` of values x (T,) added (rad); `approach` as
    in `basis`."""
    q = np.atleast_2d(np.asarray(q, float))
    if not names:
        return q
    B, cols = basis(tree, names, q, approach)
    out = q.copy()
    np.add.at(out.T, cols, (B * np.asarray(x, float)).T)
    return out


def describe(tree, name: str, value: float, std: float | None) -> dict:
    """One term of the sidecar and the report: joint, family, value, σ, unit and what it means."""
    joint, kind = name.rsplit(".", 1)
    out = {"joint": joint, "family": KINDS[kind], "parameter": name, "term": kind, "value": float(value),
           "std": None if std is None else float(std), "unit": UNITS[kind]}
    if kind == "coupling":
        out["driver"] = driver(tree, joint)
    what = {"ecc_sin": "δq = a·sin q, a", "ecc_cos": "δq = b·cos q, b", "scale": "δq = s·q, s",
            "coupling": f"δq = κ·q({out.get('driver')}), κ", "backlash": "δq = b·d/2, play b"}[kind]
    sig = "" if std is None else f" ± {std * (1e3 if kind.startswith(('ecc', 'backlash')) else 1):.2g}"
    if kind == "backlash":
        out["reading"] = f"{joint}: backlash {what} = {value * 1e3:.3f}{sig} mrad"
    elif kind.startswith("ecc"):
        out["reading"] = f"{joint}: encoder eccentricity {what} = {value * 1e3:.3f}{sig} mrad"
    else:
        out["reading"] = f"{joint}: {KINDS[kind].replace('-', ' ')} {what} = {value:.3g}{sig}"
    return out
