"""The robot itself in rerun: a serial arm drawn from its model, nominal and calibrated side by side.

Geometry (pure numpy, frames in the run's ``world``: the instrument / jig frame, m):

- `skeleton(kin, x, q)`: every frame of the chain at each posture: a URDF arm's root link, each
  joint's child link and the tool point (`UrdfArm.link_frames`); seed 000's D-H arm's base, joint
  frames and tool (`serial_arm.frames`);
- `segments(frames)`: the capsules between consecutive frame origins (links), as translations,
  unit quaternions (x, y, z, w) turning +z onto the link and lengths.

The real robots' URDFs ship meshes robocal does not have, so each link is drawn as a capsule
between its joint frames — the kinematic skeleton the calibration actually changed.

Logged (rerun-sdk 0.41), on the recording's ``time`` timeline, one step per posture of the
campaign (the measurement postures, or the encoder stream at a few Hz where the recording has one):

- ``world/robot/<nominal|calibrated>/links`` Capsules3D; ``…/joints`` Points3D at each movable
  joint's frame, labelled with the joint's name; ``…/tool`` the tool frame's axes (Arrows3D);
  a tree with several tips (`UrdfTree`) draws every chain root → tip under
  ``world/robot/<nominal|calibrated>/<tip link>/{links,joints,tool}``, the links and joints a chain
  shares with an earlier one (a torso) drawn once, with the first chain;
- ``world/robot/<calibrated, or the only robot drawn>/root`` the root link's axes (static, first posture — the base does not
  move) and ``world/instrument`` the instrument's own axes at the world origin.

"nominal" is the robot as built seen through the same registration as "before calibration"
(`pipeline.identify.model.uncalibrated`), so the two robots stand at the same place and their
difference is the calibration, not the instrument's offset.
"""

from __future__ import annotations

import numpy as np
import rerun as rr

from pipeline.models import serial_arm

TIMELINE = "time"
COLORS = {"nominal": (220, 80, 60, 255), "calibrated": (60, 110, 200, 150)}  # the nominal shows through
LINK_RADIUS_M = 0.02
AXIS_RGB = [(220, 40, 40), (40, 180, 40), (40, 80, 220)]
PALETTE = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75),
           (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207)]


def skeleton(kin, x: np.ndarray, q: np.ndarray, k: int = 0) -> tuple[list[str], list[str], np.ndarray]:
    """(frame names, movable joint names each frame follows or "", frames (N, F, 4, 4) m); a tree's
    chain root → tip `k`."""
    q = np.atleast_2d(np.asarray(q, float))
    if hasattr(kin, "link_frames"):
        names, F = kin.link_frames(x, q, k) if hasattr(kin, "descs") else kin.link_frames(x, q)
        desc = kin.desc if hasattr(kin, "desc") else kin.descs[k]
        moving = {j.child: j.name for j in desc.movable}
        return names, [moving.get(n, "") for n in names], F
    F = serial_arm.frames(np.asarray(x, float), q)
    joints = [j.name for j in kin.joints]
    return ["base"] + joints + ["tool"], [""] + joints + [""], F


def quaternion_z_to(d: np.ndarray) -> np.ndarray:
    """Unit quaternions (…, 4) xyzw turning +z onto the unit vectors d (…, 3); −z is a half
    turn about x."""
    d = np.asarray(d, float)
    w = 1.0 + d[..., 2]
    q = np.stack([-d[..., 1], d[..., 0], np.zeros_like(w), w], axis=-1)  # (z × d, 1 + z·d)
    flip = w < 1e-9
    q[flip] = (1.0, 0.0, 0.0, 0.0)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def segments(frames: np.ndarray, min_length_m: float = 1e-6) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Links as capsules between consecutive frame origins of (N, F, 4, 4) frames: which segments
    (indices i: frame i → i+1, those longer than `min_length_m` at some posture), and per posture
    translations (N, S, 3), quaternions (N, S, 4) and lengths (N, S), m."""
    p = frames[:, :, :3, 3]
    d = p[:, 1:] - p[:, :-1]
    L = np.linalg.norm(d, axis=-1)
    keep = np.flatnonzero(L.max(axis=0) > min_length_m)
    d, L = d[:, keep], L[:, keep]
    u = np.where(L[..., None] > 0, d / np.where(L > 0, L, 1)[..., None], (0.0, 0.0, 1.0))
    return keep, p[:, keep], quaternion_z_to(u), L


def axes(frames: np.ndarray, length_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Origins and vectors (…, 3, 3) of the x, y, z axes of 4×4 frames (…, 4, 4), `length_m` long."""
    o = np.repeat(frames[..., None, :3, 3], 3, axis=-2)
    v = np.swapaxes(frames[..., :3, :3], -1, -2) * length_m  # rows: the frame's axes in world
    return o, v


def _times(t_ns: np.ndarray) -> rr.TimeColumn:
    return rr.TimeColumn(TIMELINE, timestamp=np.asarray(t_ns, np.int64).astype("datetime64[ns]"))


def _partitioned(columns, n: int, k: int):
    return columns.partition(np.full(n, k, int))


def tips_of(kin) -> list[str]:
    """The tip links of a tree with several tips; [] for one chain (drawn at the unchanged paths)."""
    tips = list(getattr(kin, "tips", []) or [])
    return tips if len(tips) > 1 else []


def log_urdf_robots(rec: rr.RecordingStream, kin, x_kin: dict[str, np.ndarray], q: np.ndarray, t_ns: np.ndarray,
                    mesh_path: list[str] | tuple = (), base=None) -> list[str]:
    """A URDF robot (a chain or a tree) through rerun's URDF support (`pipeline.visualize.urdf_scene`): each
    of `x_kin` ("nominal"/"calibrated" → parameter vector) from its own calibrated URDF text, placed at its
    registration, its joints moving at postures q (N, read joints) on `time` t_ns (N,)."""
    from pipeline.visualize.urdf_scene import log_urdf_robot, mesh_dirs

    q = np.atleast_2d(np.asarray(q, float))
    dirs = mesh_dirs(mesh_path)
    paths: list[str] = []
    tree = hasattr(kin, "descs")
    qf = kin.expand(q) if tree else q
    joints = [j.name for j in kin.all_joints] if tree else list(kin.joint_names)
    for which, x in x_kin.items():
        names, F = kin.link_frames(x, q[:1], 0) if tree else kin.link_frames(x, q[:1])
        p, _ = log_urdf_robot(rec, which, kin.urdf_text(x), names[0], F[0, 0], joints, qf, t_ns, dirs, base)
        paths += p
    o, v = axes(np.eye(4), 0.2)
    rec.log("world/instrument", rr.Arrows3D(origins=o, vectors=v, colors=AXIS_RGB, radii=[0.004],
                                            labels=["instrument x", "y", "z"]), static=True)
    return paths + ["world/instrument"]


def log_robot(rec: rr.RecordingStream, kin, x_kin: dict[str, np.ndarray], q: np.ndarray, t_ns: np.ndarray,
              scale_m: float | None = None, mesh_path: list[str] | tuple = ()) -> list[str]:
    """Both robots (`x_kin`: "nominal"/"calibrated" → kinematic parameter vector) at postures q
    (N, n_joints) on `time` t_ns (N,), every chain of a tree; returns the entity paths logged (see
    module docstring).  A URDF robot (one with `urdf_text`) through rerun's URDF support
    (`log_urdf_robots`); seed 000's D-H arm as capsules."""
    if hasattr(kin, "urdf_text") and hasattr(kin, "link_frames"):
        return log_urdf_robots(rec, kin, x_kin, q, t_ns, mesh_path)
    q = np.atleast_2d(np.asarray(q, float))
    t = np.asarray(t_ns, np.int64)
    paths: list[str] = []
    reach = None
    primary = list(x_kin)[-1]  # labelled, with the root's axes: the calibrated robot when both are drawn
    tips = tips_of(kin)
    for which, x in x_kin.items():
        drawn: set[str] = set()  # frames of earlier chains (a tree's shared links are drawn once)
        for k in range(max(1, len(tips))):
            names, follows, F = skeleton(kin, x, q, k)
            if reach is None:
                reach = float(np.max(np.linalg.norm(F[:, :, :3, 3] - F[:, :1, :3, 3], axis=-1)))
                scale_m = scale_m or max(reach, 0.05)
            base = f"world/robot/{which}"
            radius = LINK_RADIUS_M * scale_m if which == "calibrated" else 0.45 * LINK_RADIUS_M * scale_m
            chain = f"{base}/{tips[k]}" if tips else base
            own = [n not in drawn or n == "tool" for n in names]
            paths += _log_chain(rec, chain, names, follows, F, t, own, which, radius, scale_m, which == primary)
            drawn |= set(names[:-1])
            if which == primary and k == 0:
                o, v = axes(F[0, 0], 0.2 * scale_m)
                rec.log(f"{base}/root", rr.Arrows3D(origins=o, vectors=v, colors=AXIS_RGB, radii=[0.2 * radius],
                                                    labels=[f"{names[0]} x", "y", "z"]), static=True)
                paths.append(f"{base}/root")
    o, v = axes(np.eye(4), 0.2 * (scale_m or 1.0))
    rec.log("world/instrument", rr.Arrows3D(origins=o, vectors=v, colors=AXIS_RGB, radii=[0.004 * (scale_m or 1.0)],
                                            labels=["instrument x", "y", "z"]), static=True)
    paths.append("world/instrument")
    return paths


def _log_chain(rec, base: str, names: list[str], follows: list[str], F: np.ndarray, t: np.ndarray, own: list[bool],
               which: str, radius: float, scale_m: float, labelled: bool) -> list[str]:
    """One chain's links (the segments ending at a frame no earlier chain drew), joints and tool axes."""
    n = len(F)
    rgba = COLORS.get(which, (120, 120, 120, 255))
    keep, tr, quat, L = segments(F)
    sel = np.array([own[i + 1] for i in keep], bool)
    keep, tr, quat, L = keep[sel], tr[:, sel], quat[:, sel], L[:, sel]
    paths = []
    labels = [f"{names[i]} → {names[i + 1]}" for i in keep]
    rec.log(f"{base}/links", rr.Capsules3D.from_fields(radii=[radius], colors=[rgba], labels=labels,
                                                       show_labels=False), static=True)
    rec.send_columns(f"{base}/links", indexes=[_times(t)], columns=_partitioned(rr.Capsules3D.columns(
        translations=tr.reshape(-1, 3), quaternions=quat.reshape(-1, 4), lengths=L.reshape(-1)), n, len(keep)))
    paths.append(f"{base}/links")
    jmask = np.array([bool(f) and o for f, o in zip(follows, own)])
    if jmask.any():
        jl = [f for f, m in zip(follows, jmask) if m]
        rec.log(f"{base}/joints", rr.Points3D.from_fields(radii=[1.3 * radius], colors=[rgba], labels=jl,
                                                          show_labels=labelled), static=True)
        rec.send_columns(f"{base}/joints", indexes=[_times(t)], columns=_partitioned(
            rr.Points3D.columns(positions=F[:, jmask, :3, 3].reshape(-1, 3)), n, int(jmask.sum())))
        paths.append(f"{base}/joints")
    o, v = axes(F[:, -1], 0.15 * scale_m)
    rec.log(f"{base}/tool", rr.Arrows3D.from_fields(colors=AXIS_RGB, radii=[0.15 * radius]), static=True)
    rec.send_columns(f"{base}/tool", indexes=[_times(t)], columns=_partitioned(
        rr.Arrows3D.columns(origins=o.reshape(-1, 3), vectors=v.reshape(-1, 3)), n, 3))
    paths.append(f"{base}/tool")
    return paths


def postures(table: dict, encoder: dict | None, joint_names: list[str], rate_hz: float = 5.0
             ) -> tuple[np.ndarray, np.ndarray]:
    """The campaign's postures to animate: the encoder stream decimated to `rate_hz` when the
    recording has one for every joint, else the measurement postures (joint readings, rad or m;
    times ns)."""
    from pipeline.visualize.scene import decimate

    if encoder is not None and all(f"q_{n}" in encoder for n in joint_names):
        t = np.asarray(encoder["t_ns"], np.int64)
        idx = decimate(t, rate_hz)
        return np.column_stack([np.asarray(encoder[f"q_{n}"], float)[idx] for n in joint_names]), t[idx]
    q = np.asarray(table["joint_positions"], float)
    t = np.asarray(table.get("timestamp_ns", np.arange(len(q)) * 1_000_000_000), np.int64)
    return q, t


def kinematics(model, x: np.ndarray):
    """(the model's serial arm, its parameter vector inside x), or None for models whose robot is
    not a serial arm drawn in the run's world (a Delta, or an arm seen through a tracker
    registration: their system hooks draw them)."""
    kin = getattr(model, "kin", None)
    if kin is not None and hasattr(model, "split") and not hasattr(model, "parts") and (
            hasattr(kin, "link_frames") or hasattr(kin, "joints")):
        return kin, np.asarray(model.split(x)[0], float)
    arm = getattr(model, "arm", None)
    if arm is not None and hasattr(model, "_arm_vector") and (hasattr(arm, "link_frames") or hasattr(arm, "joints")):
        return arm, np.asarray(model._arm_vector(np.asarray(x, float)), float)
    return None


def joint_units(kin) -> list[str]:
    """Unit of each read joint: m (prismatic) or rad (a chain's movable joints, a tree's read joints)."""
    if hasattr(kin, "all_joints"):
        read = set(kin.joint_names)
        joints = [j for j in kin.all_joints if j.name in read]
    else:
        joints = getattr(getattr(kin, "desc", None), "movable", getattr(kin, "joints", []))
    return ["m" if getattr(j, "type", "") == "prismatic" else "rad" for j in joints]


def joint_names_of(kin) -> list[str]:
    return list(getattr(kin, "joint_names", None) or [j.name for j in kin.joints])


def log_postures(rec: rr.RecordingStream, table: dict, joint_names: list[str], joint_units: list[str]) -> list[str]:
    """Without an encoder stream: the joint readings of each measurement posture on `time`
    (rad, prismatic joints m), one series per joint named by the robot's own joint names."""
    q = np.asarray(table.get("joint_positions", np.zeros((0, 0))), float)
    t = np.asarray(table.get("timestamp_ns", []), np.int64)
    if q.ndim != 2 or q.shape[0] == 0 or t.size != q.shape[0] or len(joint_names) != q.shape[1]:
        return []
    path = "encoder/postures"
    rec.log(path, rr.SeriesLines(colors=[PALETTE[i % len(PALETTE)] for i in range(len(joint_names))],
                                 names=[f"{n} ({u})" for n, u in zip(joint_names, joint_units)]), static=True)
    rec.send_columns(path, indexes=[_times(t)], columns=rr.Scalars.columns(scalars=q))
    return [path]


def nominal_registered(model, table: dict, nominal: np.ndarray, warnings: list[str]) -> np.ndarray:
    """The nominal robot as "before calibration" sees it: with the instrument's registration (and
    what else must be known before any comparison, `uncalibrated`) fitted, so nominal and
    calibrated stand in the same frame; the bare nominal vector where that fit fails."""
    from pipeline.identify.model import uncalibrated

    if getattr(model, "uncalibrated", None) is None:
        return nominal
    try:
        x = np.asarray(uncalibrated(model, table), float)
        return x if x.shape == nominal.shape and np.all(np.isfinite(x)) else nominal
    except Exception as e:  # a drawing aid must not lose the rest of the recording
        warnings.append(f"nominal robot drawn unregistered: {type(e).__name__}: {e}")
        return nominal


def log_robots(rec: rr.RecordingStream, model, table: dict, x_before: np.ndarray, x_after: np.ndarray,
               encoder: dict | None, warnings: list[str], rate_hz: float = 5.0,
               mesh_path: list[str] | tuple = ()) -> list[str]:
    """The serial arm, nominal and calibrated, along the campaign; without an encoder stream, the
    measurement postures as joint series too (`log_postures`)."""
    k0, k1 = kinematics(model, x_before), kinematics(model, x_after)
    if k0 is None or k1 is None or "joint_positions" not in table:
        return []
    kin = k1[0]
    paths = []
    if encoder is None:
        paths += log_postures(rec, table, joint_names_of(kin), joint_units(kin))
    try:
        q, t = postures(table, encoder, joint_names_of(kin), rate_hz)
        return paths + log_robot(rec, kin, {"nominal": k0[1], "calibrated": k1[1]}, q, t, mesh_path=mesh_path)
    except Exception as e:  # a drawing error must not lose the rest of the recording
        warnings.append(f"robot not drawn: {type(e).__name__}: {e}")
        return paths
