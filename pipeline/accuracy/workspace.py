"""Where the user will work: configurations over which the accuracy map is evaluated.

Each system gets a sampled grid over its working volume (or the user's targets, points in
the model's point frame, m): the arc welder's jig volume reached by inverse kinematics with
the tool orientations it was measured with; the Delta's measured box reached by its
closed-form inverse; for the scanner, every measured pose × a pixel grid over the
image region where the stripe met the targets (the volume the scanner measured).  A system without a map falls back to the measured
configurations.  Returns a measurement table that the model's `points` accepts.
"""

from __future__ import annotations

import numpy as np

from pipeline.errors import RobocalError


def _grid(lo: np.ndarray, hi: np.ndarray, n: tuple[int, int, int]) -> np.ndarray:
    axes = [np.linspace(a, b, k) if k > 1 else np.array([(a + b) / 2]) for a, b, k in zip(lo, hi, n)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def jig_box(fixture: dict, above_m: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Bounding box (m) of a touch jig's faces, extended `above_m` over its top."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for f in fixture["faces"]:
        a = "xyz".index(f["axis"])
        others = [i for i in range(3) if i != a]
        lo[a], hi[a] = min(lo[a], f["coordinate"]), max(hi[a], f["coordinate"])
        for i, (e0, e1) in zip(others, f["extent"]):
            lo[i], hi[i] = min(lo[i], e0), max(hi[i], e1)
    hi[2] += above_m
    return lo, hi


def _arc_welder(model, x: np.ndarray, data: dict, targets: np.ndarray | None, fixture: dict | None,
                n: tuple[int, int, int]) -> tuple[dict, str]:
    from pipeline.models import ik, serial_arm

    q_meas = np.asarray(data["joint_positions"], float)
    R_m, p_m = serial_arm.forward(x, q_meas)
    if targets is None:
        if fixture is None:
            raise RobocalError("accuracy map: the recording has no fixture to grid")
        lo, hi = jig_box(fixture)
        targets, what = _grid(lo, hi, n), f"jig volume grid {n[0]}×{n[1]}×{n[2]} (faces' box, +50 mm over the top)"
    else:
        what = f"{len(targets)} user targets"
    # orientation of the nearest measured tip; seeds: the nearest measured configurations
    d = np.linalg.norm(targets[:, None, :] - p_m[None], axis=2)
    order = np.argsort(d, axis=1)
    arm = model.arm
    lower = np.array([j.lower for j in arm.joints])
    upper = np.array([j.upper for j in arm.joints])
    q = np.zeros((len(targets), q_meas.shape[1]))
    ok = np.zeros(len(targets), bool)
    seeds = q_meas[np.linspace(0, len(q_meas) - 1, min(8, len(q_meas))).astype(int)]
    for k in range(min(3, len(q_meas))):  # the 3 nearest measured orientations in turn
        todo = np.flatnonzero(~ok)
        if todo.size == 0:
            break
        near = order[todo, k]
        qk, okk = ik.solve(x, targets[todo], R_m[near], seeds, lower, upper)
        q[todo[okk]], ok[todo[okk]] = qk[okk], True
    if not ok.any():
        raise RobocalError("accuracy map: no grid point or target is reachable by the calibrated model")
    return {"joint_positions": q[ok]}, what + (f"; {int((~ok).sum())} unreachable dropped" if (~ok).any() else "")


def _delta(model, x: np.ndarray, data: dict, targets: np.ndarray | None, n: tuple[int, int, int]):
    from pipeline.models import delta as dm
    from pipeline.measurements.registration import registration_matrix

    beta, reg, _ = model._split(x)
    b = model._simplified_beta(beta)
    theta = np.asarray(data["joint_positions"], float)
    p_a, _ = dm.forward(model.delta, b, theta)
    if targets is None:
        lo, hi = p_a.min(axis=0), p_a.max(axis=0)
        pts, what = _grid(lo, hi, n), f"measured-volume grid {n[0]}×{n[1]}×{n[2]}"
    else:  # user targets in the tracker / workcell frame {T} → {A}
        R, t = registration_matrix(reg)
        pts, what = targets @ R.T + t, f"{len(targets)} user targets"
    th, ok = dm.inverse(model.delta, b, pts)
    if not ok.any():
        raise RobocalError("accuracy map: no grid point or target is reachable by the calibrated Delta")
    return {"joint_positions": th[ok]}, what + (f"; {int((~ok).sum())} unreachable dropped" if (~ok).any() else "")


def _scanner(model, x: np.ndarray, data: dict, targets, n: tuple[int, int, int]):
    if targets is not None:
        raise RobocalError("accuracy map: the scanner maps its image over the measured poses; user targets "
                           "are not supported for it")
    q = np.unique(np.round(np.asarray(data["joint_positions"], float), 9), axis=0)
    pm = np.asarray(data["pixel"], float)
    lo, hi = pm.min(axis=0), pm.max(axis=0)  # the image region where the stripe met the targets
    u, v = np.meshgrid(np.linspace(lo[0], hi[0], n[0]), np.linspace(lo[1], hi[1], n[1]))
    px = np.stack([u.ravel(), v.ravel()], axis=1)
    table = {"joint_positions": np.repeat(q, len(px), axis=0), "pixel": np.tile(px, (len(q), 1))}
    # a pixel off the stripe meets the laser plane anywhere (near-parallel rays: metres away): keep the points
    # inside the measured points' box grown by half its size and 20 mm
    p_meas, _ = model.points(x, data)
    p_map, _ = model.points(x, table)
    lo, hi = p_meas.min(axis=0), p_meas.max(axis=0)
    pad = 0.5 * (hi - lo) + 0.02  # m; the target pattern is flat
    keep = np.all((p_map >= lo - pad) & (p_map <= hi + pad), axis=1)
    if not keep.any():
        return {k: np.asarray(data[k]) for k in ("joint_positions", "pixel")}, "measured image points"
    table = {k: v[keep] for k, v in table.items()}
    return table, (f"{len(q)} measured poses × {len(px)} image points (grid over the measured pixels' box), "
                   f"{int(keep.sum())} inside the measured volume grown by half its size + 20 mm")


def map_table(model, x: np.ndarray, data: dict, targets: np.ndarray | None = None, fixture: dict | None = None,
              n: tuple[int, int, int] = (6, 5, 3)) -> tuple[dict, str]:
    """(table of map configurations, description) for the system of `model` at estimate x."""
    system = getattr(model, "system", "")
    x = np.asarray(x, float)
    if targets is not None:
        targets = np.atleast_2d(np.asarray(targets, float))
    if system == "arc-welder" and hasattr(model, "arm"):
        return _arc_welder(model, x, data, targets, fixture, n)
    if system == "delta-tracker":
        return _delta(model, x, data, targets, n)
    if system == "scorbot-scanner":
        return _scanner(model, x, data, targets, n)
    if targets is not None:
        raise RobocalError(f"accuracy map: system {system} cannot place user targets; omit --targets")
    return dict(data), "measured configurations (no workspace map for this system)"


def spread_table(model, data: dict, n: int = 200, seed: int = 0) -> dict | None:
    """n configurations drawn uniformly within the arm's joint limits (±π where a joint has none),
    the other columns as the first measurement's: where a campaign *could* measure, for counting the
    parameters a full model identifies.  None for a model without an arm's joint limits."""
    arm = getattr(model, "arm", None) or getattr(model, "kin", None)
    q = np.asarray(data.get("joint_positions", np.zeros((0, 0))), float)
    lo, hi = getattr(arm, "lower", None), getattr(arm, "upper", None)
    if arm is None or lo is None or hi is None or q.ndim != 2 or not len(q):
        return None
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    if lo.shape != (q.shape[1],) or hi.shape != lo.shape:
        return None
    lo = np.where(np.isfinite(lo), lo, -np.pi)
    hi = np.where(np.isfinite(hi), hi, np.pi)
    table = {k: np.repeat(np.asarray(v)[:1], n, axis=0) for k, v in data.items()}
    table["joint_positions"] = np.random.default_rng(seed).uniform(lo, hi, (n, lo.size))
    return table
