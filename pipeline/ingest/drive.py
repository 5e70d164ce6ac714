"""Drive state at each measurement, from the encoder stream's optional fields (commanded positions, efforts, motor currents).

A controller that logs its drive state puts, per sample and joint, the commanded position (rad / m),
the measured effort (the drive's torque on the link, N·m; N for a prismatic joint) and the motor
current (A) into `/robot/joint_state` (`robocal.JointStateBatch` fields 7, 8 and 9).  A current is a
torque only through the joint's torque constant k (N·m/A: motor constant × gear ratio, referred to the
joint), which no URDF carries: `efforts_from_currents` converts where the campaign states k per joint.  The diagnosis needs them at each
measurement: the mean over the samples within ±`window_s`/2 of its time (the robot stands still
while it is measured, so the mean lowers the drive's noise).  Vectorised: `np.searchsorted` finds
every window, a cumulative sum gives its mean; no Python loop over measurements or samples.
"""

from __future__ import annotations

import numpy as np

from pipeline.errors import RobocalError, where
from pipeline.ingest.streams import JOINT_STATE, JointStream
from pipeline.recording.joint_state_batch import COMMANDED_POSITIONS

DEFAULT_WINDOW_S = 0.5
COLUMNS = {"effort": "joint_efforts", "q_cmd": COMMANDED_POSITIONS, "current": "joint_currents"}  # field → column
TORQUE_CONSTANTS = "torque_constants_Nm_per_A"  # campaign metadata: {joint: N·m at the joint per A of motor current}


def window_of(campaign: dict, path) -> float:
    """The averaging window, s: the ROS 2 import's standstill window (campaign `ros2.pairing.window_s`)
    where the recording came from a bag, else `DEFAULT_WINDOW_S`; a bad value is a one-line error."""
    ros2 = campaign.get("ros2") if isinstance(campaign, dict) else None
    pairing = ros2.get("pairing") if isinstance(ros2, dict) else None
    w = pairing.get("window_s", DEFAULT_WINDOW_S) if isinstance(pairing, dict) else DEFAULT_WINDOW_S
    if isinstance(w, bool) or not isinstance(w, (int, float)) or not np.isfinite(w) or w <= 0:
        raise RobocalError(f"{path}: metadata robocal.campaign ros2.pairing.window_s {w!r} is not a positive number "
                           "of seconds")
    return float(w)


def window_means(t_ns: np.ndarray, v: np.ndarray, t_meas_ns: np.ndarray, window_s: float = DEFAULT_WINDOW_S
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(means (m, J), samples per window (m,)) of `v` (T, J) at sorted sample times `t_ns` (T,) ns over
    [t − w/2, t + w/2] around each measurement time (m,) ns; NaN rows where a window holds no sample."""
    t = np.asarray(t_ns, np.int64)
    v = np.asarray(v, float)
    tm = np.asarray(t_meas_ns, np.int64)
    half = int(round(window_s * 5e8))
    a = np.searchsorted(t, tm - half, side="left")
    b = np.searchsorted(t, tm + half, side="right")
    n = b - a
    csum = np.vstack([np.zeros((1, v.shape[1])), np.cumsum(v, axis=0)])
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (csum[b] - csum[a]) / n[:, None]
    mean[n == 0] = np.nan
    return mean, n


def at_measurements(stream: JointStream, t_meas_ns: np.ndarray, joints: list[str], path, topic: str,
                    window_s: float = DEFAULT_WINDOW_S) -> dict[str, np.ndarray]:
    """{table column: (m, len(joints))} of the drive state the stream carries, in `joints` order (matched
    by name), at each measurement; {} when it carries none.  A chain joint missing from the stream, or
    a measurement without a drive sample in its window, is a `RobocalError` naming file and record."""
    have = {k: getattr(stream, k) for k in COLUMNS if getattr(stream, k) is not None}
    if not have:
        return {}
    missing = [j for j in joints if j not in stream.names]
    if missing:
        raise RobocalError(f"{where(path, JOINT_STATE)}: drive state lacks chain joint(s) {', '.join(missing)} "
                           f"(stream joints: {', '.join(stream.names)})")
    cols = np.array([stream.names.index(j) for j in joints], np.intp)
    order = np.argsort(stream.t_ns, kind="stable")
    t = stream.t_ns[order]
    out = {}
    for key, v in have.items():
        mean, n = window_means(t, v[order][:, cols], t_meas_ns, window_s)
        empty = np.flatnonzero(n == 0)
        if empty.size:
            raise RobocalError(f"{where(path, topic, int(empty[0]))}: no {JOINT_STATE} drive sample within "
                               f"±{window_s / 2:g} s of the measurement")
        out[COLUMNS[key]] = mean
    return out


def efforts_from_currents(currents: np.ndarray, joints: list[str], constants: dict, path) -> np.ndarray:
    """Efforts (m, J) N·m = k_j · current_j (A) with the campaign's torque constants k (N·m/A) per joint;
    a chain joint without a finite k is a `RobocalError` naming the file and the metadata field."""
    bad = [j for j in joints if not isinstance(constants.get(j), (int, float)) or not np.isfinite(constants[j])]
    if bad:
        raise RobocalError(f"{path}: metadata robocal.campaign: {TORQUE_CONSTANTS} has no finite value for "
                           f"{', '.join(bad)} (N·m/A for every chain joint)")
    return np.asarray(currents, float) * np.array([float(constants[j]) for j in joints])
