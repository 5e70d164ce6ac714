"""An excitation trajectory as the robot runs it: sampled from rest to rest, checked, written as a CSV
table and as a ROS 2 bag of one ``trajectory_msgs/msg/JointTrajectory`` (rosbags' own writer), and the
self-collision check of a URDF with collision geometry (Pinocchio + coal).

Units SI: s, rad (m), rad/s (m/s), rad/s² (m/s²).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError
from pipeline.plan.excitation import Fourier, Limits

T0_NS = 1_700_000_000_000_000_000


def limits_of(urdf_text: str, joints: list[str], acceleration: float | dict, velocity_scale: float = 1.0,
              margin: float = 0.05, source: str = "URDF") -> Limits:
    """The joints' limits from the URDF (`<limit lower upper velocity>`, read by Pinocchio), velocities ×
    `velocity_scale`; accelerations (a URDF has none) from `acceleration` (one value, or {joint: value}).
    A joint without position or velocity limits is one line naming it."""
    import pinocchio as pin

    m = pin.buildModelFromXML(urdf_text)
    lo, hi, vel, acc = [], [], [], []
    for name in joints:
        jm = m.joints[m.getJointId(name)]
        i, iv = jm.idx_q, jm.idx_v
        low, up, v = float(m.lowerPositionLimit[i]), float(m.upperPositionLimit[i]), float(m.velocityLimit[iv])
        if jm.nq != 1 or not np.isfinite([low, up]).all() or up <= low or abs(up - low) > 1e6:
            raise RobocalError(f"{source}: joint {name!r} has no position limits (<limit lower upper>): "
                               "an excitation needs the range it may use")
        if not np.isfinite(v) or v <= 0 or v > 1e6:
            raise RobocalError(f"{source}: joint {name!r} has no velocity limit (<limit velocity>)")
        lo.append(low)
        hi.append(up)
        vel.append(v * velocity_scale)
        acc.append(float(acceleration.get(name, np.nan)) if isinstance(acceleration, dict) else float(acceleration))
    if not np.all(np.isfinite(acc)) or min(acc) <= 0:
        raise RobocalError("--max-acceleration: a positive acceleration limit per joint is needed")
    return Limits(np.array(lo), np.array(hi), np.array(vel), np.array(acc), margin)


def sample(f: Fourier, rate_hz: float, periods: int, rest_s: float) -> tuple[np.ndarray, ...]:
    """(t, q, q̇, q̈) of `rest_s` at rest at q(0), `periods` periods, `rest_s` at rest again, at `rate_hz`."""
    dt = 1.0 / rate_hz
    n_rest = int(round(rest_s * rate_hz))
    n_move = int(round(periods * f.period * rate_hz))
    tm = np.arange(n_move + 1) * dt
    q, v, a = f.states(tm)
    q_start, _, _ = f.states(np.zeros(1))
    rest_q = np.repeat(q_start, n_rest, axis=0)
    zeros = np.zeros_like(rest_q)
    t = np.arange(2 * n_rest + n_move + 1) * dt
    return (t, np.vstack([rest_q, q, rest_q]), np.vstack([zeros, v, zeros]), np.vstack([zeros, a, zeros]))


def violations(q: np.ndarray, v: np.ndarray, a: np.ndarray, lim: Limits, tol: float = 1e-9) -> list[str]:
    """Every limit the samples exceed (empty: within limits)."""
    out = []
    for j in range(q.shape[1]):
        for what, bad in (("position", (q[:, j] < lim.lower[j] - tol) | (q[:, j] > lim.upper[j] + tol)),
                          ("velocity", np.abs(v[:, j]) > lim.velocity[j] + tol),
                          ("acceleration", np.abs(a[:, j]) > lim.acceleration[j] + tol)):
            if bad.any():
                out.append(f"joint {j}: {what} beyond its limit at {int(bad.sum())} samples")
    return out


def write_csv(path: Path, joints: list[str], t, q, v, a) -> None:
    """t and per joint JOINT_position, JOINT_velocity, JOINT_acceleration (SI): a table `robocal import csv`
    and `robocal simulate dynamics --trajectory` read."""
    head = ["t"] + [f"{j}_{k}" for k in ("position", "velocity", "acceleration") for j in joints]
    rows = np.column_stack([t, q, v, a])
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(",".join(head) + "\n")
        np.savetxt(fh, rows, delimiter=",", fmt="%.10g")


def read_csv(path: Path, joints: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(t (T,), q (T, J), q̇, q̈ (T, J) or None) of a trajectory table (columns t and JOINT_position per joint;
    JOINT_velocity and JOINT_acceleration when every joint has them); one line on a missing column, a value
    that is not a number or times that do not increase."""
    import csv

    with open(path, newline="", encoding="utf-8") as fh:
        header = [h.strip() for h in next(csv.reader(fh), [])]
    need = ["t"] + [f"{j}_position" for j in joints]
    missing = [c for c in need if c not in header]
    if missing:
        raise RobocalError(f"{path}: missing column(s) {', '.join(missing)}")
    data = np.genfromtxt(path, delimiter=",", skip_header=1, ndmin=2)
    cols = [header.index(c) for c in need]
    if data.shape[0] < 10 or not np.all(np.isfinite(data[:, cols])):
        raise RobocalError(f"{path}: fewer than 10 rows, or a value that is not a number")
    t = data[:, cols[0]]
    if np.any(np.diff(t) <= 0):
        raise RobocalError(f"{path}: row {int(np.flatnonzero(np.diff(t) <= 0)[0]) + 2}: times not increasing")
    out = [t, data[:, cols[1:]]]
    for kind in ("velocity", "acceleration"):
        names = [f"{j}_{kind}" for j in joints]
        ok = all(n in header for n in names) and np.all(np.isfinite(data[:, [header.index(n) for n in names]]))
        out.append(data[:, [header.index(n) for n in names]] if ok else None)
    return tuple(out)


def write_bag(path: Path, joints: list[str], t, q, v, a, topic: str = "/joint_trajectory") -> None:
    """A rosbag2 (MCAP storage) holding one trajectory_msgs/msg/JointTrajectory with every sample as a
    point (positions, velocities, accelerations, time_from_start), written by rosbags' Writer."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.LATEST)
    T = store.types
    Dur = T["builtin_interfaces/msg/Duration"]
    pts = []
    for i in range(t.size):
        ns = int(round(t[i] * 1e9))
        pts.append(T["trajectory_msgs/msg/JointTrajectoryPoint"](
            positions=np.asarray(q[i], float), velocities=np.asarray(v[i], float),
            accelerations=np.asarray(a[i], float), effort=np.zeros(0),
            time_from_start=Dur(sec=ns // 10**9, nanosec=ns % 10**9)))
    hdr = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=T0_NS // 10**9, nanosec=0), frame_id="")
    msg = T["trajectory_msgs/msg/JointTrajectory"](header=hdr, joint_names=list(joints), points=pts)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection(topic, "trajectory_msgs/msg/JointTrajectory", typestore=store)
        w.write(c, T0_NS, bytes(store.serialize_cdr(msg, "trajectory_msgs/msg/JointTrajectory")))


def read_bag(path: Path, topic: str = "/joint_trajectory") -> tuple[list[str], np.ndarray, np.ndarray]:
    """(joint names, t (T,), q (T, J)) of the first JointTrajectory on `topic` (rosbags' Reader)."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.LATEST)
    with Reader(path) as r:
        for conn, _, raw in r.messages(connections=[c for c in r.connections if c.topic == topic]):
            m = store.deserialize_cdr(raw, conn.msgtype)
            t = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in m.points])
            return list(m.joint_names), t, np.array([p.positions for p in m.points])
    raise RobocalError(f"{path}: no {topic} JointTrajectory")


def self_collision(urdf_text: str, joints: list[str], package_dirs: list[str] | None = None):
    """A function q (T, J) → (T,) bool, True where two non-adjacent links' collision geometries intersect
    (pairs already in contact at the range's middle are left out: they touch by design), or (None, why)
    when the URDF's collision geometry cannot be loaded (meshes absent) or it has none."""
    import pinocchio as pin

    try:
        full = pin.buildModelFromXML(urdf_text)
        geom = pin.buildGeomFromUrdfString(full, urdf_text, pin.GeometryType.COLLISION, package_dirs=package_dirs or [])
    except (RuntimeError, ValueError, OSError) as e:
        return None, f"collision geometry not loaded ({str(e).splitlines()[0][:120]})"
    if len(geom.geometryObjects) < 2:
        return None, "the URDF has no collision geometry"
    lock = [full.getJointId(n) for n in list(full.names)[1:] if n not in joints]
    mid = pin.neutral(full)
    model, geom = pin.buildReducedModel(full, geom, lock, mid) if lock else (full, geom)
    geom.addAllCollisionPairs()
    objs = geom.geometryObjects
    keep = []
    for k, cp in enumerate(geom.collisionPairs):
        j1, j2 = objs[cp.first].parentJoint, objs[cp.second].parentJoint
        if j1 == j2 or model.parents[j1] == j2 or model.parents[j2] == j1:
            continue
        keep.append(k)
    pairs = [geom.collisionPairs[k] for k in keep]
    geom.removeAllCollisionPairs()
    for cp in pairs:
        geom.addCollisionPair(cp)
    idx = [model.joints[model.getJointId(j)].idx_q for j in joints]
    data, gdata = model.createData(), pin.GeometryData(geom)

    def hits(qj: np.ndarray) -> np.ndarray:
        out = np.zeros(qj.shape[0], bool)
        for i, row in enumerate(np.atleast_2d(qj)):
            qq = pin.neutral(model)
            qq[idx] = row
            out[i] = pin.computeCollisions(model, data, geom, gdata, qq, True)
        return out

    lo = np.array([model.lowerPositionLimit[i] for i in idx])
    hi = np.array([model.upperPositionLimit[i] for i in idx])
    qmid = np.where(np.isfinite(lo + hi), 0.5 * (lo + hi), 0.0)
    if hits(qmid[None])[0]:  # pairs in contact at the middle of the range touch by design: leave them out
        qq = pin.neutral(model)
        qq[idx] = qmid
        pin.computeCollisions(model, data, geom, gdata, qq, False)
        touching = [k for k, r in enumerate(gdata.collisionResults) if r.isCollision()]
        geom.removeAllCollisionPairs()
        for k, cp in enumerate(pairs):
            if k not in touching:
                geom.addCollisionPair(cp)
        gdata = pin.GeometryData(geom)
    return hits, f"{len(geom.collisionPairs)} collision pairs of non-adjacent links checked"
