"""A calibration campaign of a URDF robot as a real ROS 2 bag (tests, benchmarks, examples).

The robot moves from stop to stop (cosine velocity profile, `move_s`), dwells `dwell_s` at each, and
the instrument measures the true tool point (or pose) in the middle of the dwell.  JointState
messages at `rate_hz` carry the readings of the true joint positions (plus encoder noise); every
message is serialised by rosbags' own CDR serialiser and written with its rosbag2 `Writer` (MCAP
or SQLite3 storage), so what the importer reads is what a robot's bag holds.  The truth (parameter
vector, stop configurations) is returned, never written to the bag.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

JOINT_STATE = "sensor_msgs/msg/JointState"
POINT = "geometry_msgs/msg/PointStamped"
POSE = "geometry_msgs/msg/PoseStamped"
T0_NS = 1_750_000_000_000_000_000  # bag start (a fixed epoch: reproducible bags)


@dataclass(frozen=True)
class BagLayout:
    """How the campaign is laid out in time and on topics (s, Hz, rad)."""

    rate_hz: float = 100.0
    move_s: float = 2.0
    dwell_s: float = 2.0
    noise_q_rad: float = 0.0  # encoder noise, 1σ, on every joint reading
    joint_topic: str | None = "/joint_states"  # None: no joint states at all
    measure_topic: str = "/tracker/point"
    frame_id: str = "tracker"
    name_order: tuple[int, ...] | None = None  # permutation of the chain's joints in the messages
    extra_joints: dict[str, float] = field(default_factory=dict)  # other joints (gripper, …) at fixed values
    drop_joint: str | None = None  # a chain joint left out of the messages
    rename: dict[str, str] = field(default_factory=dict)  # chain joint -> name used in the bag
    moving: tuple[int, ...] = ()  # measurements taken mid-move (into their stop) instead of mid-dwell
    corrupt: tuple[str, int] | None = None  # (topic, record): raw bytes that are not valid CDR
    zero_stamps: tuple[str, ...] = ()  # topics whose header.stamp is left 0 (publishers that never set it)
    clock_offset_s: float = 0.0  # the instrument's clock minus the controller's (header stamps and receive times)
    description: str | None = None  # a URDF text latched on /robot_description first (as robot_state_publisher)


def timeline(q_stops: np.ndarray, layout: BagLayout) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(joint times s (n,), true joint positions (n, J), mid-dwell times (m,), mid-move times (m,))."""
    m = len(q_stops)
    T = layout.move_s + layout.dwell_s
    t = np.arange(0.0, m * T, 1.0 / layout.rate_hz)
    seg = np.minimum((t // T).astype(int), m - 1)
    tau = t - seg * T
    s = np.where(tau < layout.move_s, 0.5 - 0.5 * np.cos(np.pi * tau / layout.move_s), 1.0)
    prev = np.roll(q_stops, 1, axis=0)  # the first move comes from the last stop (a campaign that repeats)
    q = prev[seg] + s[:, None] * (q_stops[seg] - prev[seg])
    k = np.arange(m)
    return t, q, k * T + layout.move_s + layout.dwell_s / 2, k * T + layout.move_s / 2


def _header(store, t_ns: int, frame_id: str = ""):
    T = store.types
    return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=int(t_ns // 1_000_000_000),
                                                                         nanosec=int(t_ns % 1_000_000_000)),
                                    frame_id=frame_id)


def write_bag(out: str | Path, joint_names: list[str], t_joint_s: np.ndarray, q_joint: np.ndarray,
              t_meas_s: np.ndarray, positions: np.ndarray, orientations: np.ndarray | None, layout: BagLayout,
              storage: str = "mcap", effort: np.ndarray | None = None) -> Path:
    """Write the bag folder `out` (rosbag2, `storage` mcap | sqlite3); returns its storage file.
    `effort` (n, J) N·m in chain order: each JointState's effort (0 for the extra joints); else empty."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.LATEST)
    T = store.types
    order = list(layout.name_order) if layout.name_order is not None else list(range(len(joint_names)))
    names = [layout.rename.get(joint_names[k], joint_names[k]) for k in order]
    cols = list(order)
    if layout.drop_joint is not None:
        i = [joint_names[k] for k in order].index(layout.drop_joint)
        del names[i], cols[i]
    names += list(layout.extra_joints)
    extra = np.array(list(layout.extra_joints.values()), float)
    empty = np.zeros(0)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    mtype = POSE if orientations is not None else POINT
    events = []  # (t ns, kind, index)
    tj = T0_NS + np.round(np.asarray(t_joint_s) * 1e9).astype(np.int64)
    tm = T0_NS + np.round((np.asarray(t_meas_s) + layout.clock_offset_s) * 1e9).astype(np.int64)
    if layout.joint_topic is not None:
        events += [(int(t), 0, i) for i, t in enumerate(tj)]
    events += [(int(t), 1, i) for i, t in enumerate(tm)]
    events.sort()
    with Writer(Path(out), version=9, storage_plugin=plugin) as w:
        cj = w.add_connection(layout.joint_topic, JOINT_STATE, typestore=store) if layout.joint_topic else None
        cm = w.add_connection(layout.measure_topic, mtype, typestore=store)
        if layout.description is not None:
            cd = w.add_connection("/robot_description", "std_msgs/msg/String", typestore=store)
            w.write(cd, min(e[0] for e in events), bytes(store.serialize_cdr(T["std_msgs/msg/String"](
                data=layout.description), "std_msgs/msg/String")))
        count = {0: 0, 1: 0}
        for t, kind, i in events:
            topic = layout.joint_topic if kind == 0 else layout.measure_topic
            hdr = _header(store, 0 if topic in layout.zero_stamps else t, "" if kind == 0 else layout.frame_id)
            if kind == 0:
                pos = np.concatenate([q_joint[i, cols], extra])
                eff = empty if effort is None else np.concatenate([effort[i, cols], np.zeros(extra.size)])
                msg = T[JOINT_STATE](header=hdr, name=names, position=pos, velocity=empty, effort=eff)
                conn, typ = cj, JOINT_STATE
            else:
                p = T["geometry_msgs/msg/Point"](x=float(positions[i, 0]), y=float(positions[i, 1]),
                                                 z=float(positions[i, 2]))
                if orientations is None:
                    msg = T[POINT](header=hdr, point=p)
                else:
                    o = T["geometry_msgs/msg/Quaternion"](**dict(zip("xyzw", map(float, orientations[i]))))
                    msg = T[POSE](header=hdr, pose=T["geometry_msgs/msg/Pose"](position=p, orientation=o))
                conn, typ = cm, mtype
            data = bytes(store.serialize_cdr(msg, typ))
            if layout.corrupt is not None and layout.corrupt == (conn.topic, count[kind]):
                data = data[:4] + b"\xff" * 3  # a valid encapsulation header, then too few bytes for any field
            w.write(conn, t, data)
            count[kind] += 1
    return Path(out) / f"{Path(out).name}.{'mcap' if storage == 'mcap' else 'db3'}"


def simulate_bag(out: str | Path, desc, measure: str = "point", n: int = 30, seed: int = 0,
                 noise_m: float = 2e-5, noise_rad: float = 1e-4, error_m: float = 1e-3, error_rad: float = 3.5e-3,
                 layout: BagLayout = BagLayout(), storage: str = "mcap") -> dict:
    """Simulate `n` stops of the robot `desc` (a `RobotDescription`) measured by `measure` (point |
    pose) and write the bag; returns the truth: ``x`` (parameter vector), ``names``, ``q_stops`` (n, J)
    rad/m, ``storage`` (the bag's storage file), ``model``."""
    from pipeline.models.urdf_arm import UrdfArm
    from pipeline.simulate.urdf_robot import campaign, random_truth
    from pipeline.systems.urdf_robot import model_for

    model = model_for(UrdfArm(desc), measure, {"sigma_m": max(noise_m, 1e-6), "sigma_rad": max(noise_rad, 1e-6)})
    rng = np.random.default_rng(seed)
    x = random_truth(model, rng, error_m, error_rad, registration=True)
    table, _ = campaign(model, x, n, seed, measure, noise_m, noise_rad)
    q_stops = table["joint_positions"]
    t, q, t_dwell, t_move = timeline(q_stops, layout)
    tm = t_dwell.copy()
    P = table["position"].copy()
    O = table.get("orientation")
    mv = np.array(layout.moving, int)
    if len(mv):  # measured mid-move: the instrument sees the tool where the robot really is then
        tm[mv] = t_move[mv]
        i = np.searchsorted(t, t_move[mv])
        p, _, R, _ = model.tool(x, q[i])
        P[mv] = p
        if O is not None:
            from scipy.spatial.transform import Rotation

            O = O.copy()
            O[mv] = Rotation.from_matrix(R).as_quat()
    q_read = q + (rng.normal(0, layout.noise_q_rad, q.shape) if layout.noise_q_rad else 0.0)
    path = write_bag(out, desc.joint_names, t, q_read, tm, P, O, layout, storage)
    return {"x": x, "names": model.parameter_names(), "q_stops": q_stops, "storage": path, "model": model,
            "t_meas_s": tm, "n_joint_states": len(t)}
