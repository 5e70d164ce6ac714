"""Touch campaigns as users' own robot programs run them — the independent generator's second campaign
(`independent_touch` is the first): random search directions and speeds, mixed payloads, a servo's encoder stream.

Nothing of robocal's diagnosis is read here: the arm's own 4×4 kinematics, gravity and gear play are
`independent_arm`'s, the inverse kinematics and the effects' own forms `independent_touch`'s.  What differs from
`independent_touch.plan`/`run`:

- **search directions**: each search is a straight line of the tip at constant tool orientation (a controller's
  linear search), in a random direction within `cone_deg` of the face's inward normal, from a stand-off of
  15–40 mm along it — not the face normal (so every joint turns either way during a search, by its own
  amount);
- **approaches**: each approach pose is reached from a clearance pose 20–60 mm away in a random direction off the
  face (a PTP move from the previous contact to it, then a short linear move in), and the servo overshoots the
  approach pose (a damped oscillation, 10 Hz, τ 40 ms, up to 4 encoder counts per joint) before it settles; after
  the latch the arm stops 10 ms later, dwells and retracts to the approach pose;
- **speeds**: log-uniform 3–25 mm/s per search;
- **payloads**: blocks of 6–15 contacts, each with a payload drawn from `payloads` (kg) other than the block
  before (or one `payload_kg` throughout);
- **the encoder stream**: 250 Hz with 0.2 ms timing jitter and 0.3 % of samples dropped, quantised to 2¹⁷
  counts per turn; the latch reads the encoder when the probe touches;
- **gear play** (`backlash`): the link follows the motor through a dead band along this whole motor path —
  the PTP and linear moves, each overshoot's turning points, the search, the stop past the latch and the retract
  (`independent_arm.play`); a search shorter than the play leaves the link where the approach put it, and an
  overshoot shorter than the play moves nothing.

Besides `independent_touch`'s effects, this campaign's own forms of more library physics (each written here):
``eccentricity`` δq_j = A·sin(q_j + φ), ``scale`` δq_j = ε·q_j, ``transmission`` δq_j = A·sin(2q_j + φ) (where:
joint, phase φ rad), ``difference`` δq_j = k·(q_i − q_j) (where["pair"] = (i, j)), ``latency`` the latch reads the encoder `size` s after the touch (the arm has gone on at its
search speed), ``pretravel`` the probe triggers `size` m of search after the touch, ``drift`` the jig moves by
`size` m/s along where["axis"] (0/1/2) and ``face_offset`` one face (where["face"]) lies `size` m off its drawing
along its axis.

Every random choice of the motion is the plan's (`plan(seed=…)`); `run(seed=…)` draws only the noise (robot
repeatability, jig machining, stream timing), so `independent_touch.mds(..., runner=run)` computes the ideal
test's detectable size on the very motion of a noisy campaign.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from independent_arm import gravity_torque, pose, tip
from independent_touch import (
    COUNT,
    EPOCH_NS,
    RATE_HZ,
    Campaign,
    _bisect_unsettled,
    _face_shift,
    _joint_error,
    _link_scale,
    points_on_faces,
)

from independent_jig import Block as Jig
from independent_jig import stepped_block

T_PTP, T_IN, T_SETTLE, T_STOP, T_DWELL, T_BACK = 1.5, 0.6, 0.3, 0.01, 0.3, 0.8  # s
OVERSHOOT_HZ, OVERSHOOT_TAU = 10.0, 0.04  # the servo's settling oscillation


@dataclass
class Searches:
    """A campaign's plan: per contact its face, approach pose q_a (m, 6) rad, joint rate along the search dq
    (m, 6) rad per m of tip travel, search direction (m, 3) (unit, into the face, jig frame), clearance pose `via`
    (m, 6) the approach comes from, search speed (m,) m/s, servo overshoot (m, 6) rad (signed: along the move into
    q_a) and payload (m,) kg."""

    face: np.ndarray
    q_a: np.ndarray
    dq: np.ndarray
    direction: np.ndarray
    via: np.ndarray
    speed: np.ndarray
    overshoot: np.ndarray
    payload: np.ndarray

    def take(self, idx) -> "Searches":
        return Searches(*(np.asarray(getattr(self, f))[idx] for f in self.__dataclass_fields__))


def jacobian6(arm, q: np.ndarray, h: float = 1e-7) -> np.ndarray:
    """(n, 6, 6): d(tip position, m; tool rotation vector in the jig frame, rad)/dq, finite differences."""
    T0 = pose(arm, q)
    cols = []
    for j in range(6):
        T1 = pose(arm, q + h * np.eye(6)[j])
        dR = T1[:, :3, :3] @ np.swapaxes(T0[:, :3, :3], 1, 2)
        w = 0.5 * np.stack([dR[:, 2, 1] - dR[:, 1, 2], dR[:, 0, 2] - dR[:, 2, 0], dR[:, 1, 0] - dR[:, 0, 1]], 1)
        cols.append(np.concatenate([(T1[:, :3, 3] - T0[:, :3, 3]) / h, w / h], axis=1))
    return np.stack(cols, axis=2)


def _ik(arm, p: np.ndarray, w: np.ndarray, q0: np.ndarray, iters: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """Damped least squares on [tip − p, 0.3·(wire − w)] (wire = tool z), the finite-difference Jacobian of all
    rows in one batch of the forward kinematics; returns (q, converged within the joint limits)."""
    q, h, n = q0.copy(), 1e-6, q0.shape[0]
    steps = np.concatenate([np.zeros((1, 6)), h * np.eye(6)])

    def err(qq, pp, ww):
        T = pose(arm, qq)
        return np.concatenate([T[:, :3, 3] - pp, 0.3 * (T[:, :3, 2] - ww)], axis=1)

    live = np.arange(n)
    prev = np.full(n, np.inf)
    for it_ in range(iters):
        m = live.size
        E = err((q[live, None, :] + steps).reshape(-1, 6), np.repeat(p[live], 7, 0), np.repeat(w[live], 7, 0))
        E = E.reshape(m, 7, 6)
        e, J = E[:, 0], np.swapaxes((E[:, 1:] - E[:, :1]) / h, 1, 2)
        JT = np.swapaxes(J, 1, 2)
        step = np.linalg.solve(JT @ J + 1e-6 * np.eye(6), JT @ e[..., None])[..., 0]
        q[live] -= np.clip(step, -0.3, 0.3)
        en = np.linalg.norm(e, axis=1)
        # done, or (after a few steps) stalled: a start that does not converge is left to the next start
        alive = (en > 1e-12) & ((it_ < 8) | (en < 0.5 * prev[live]) | (en < 1e-6))
        prev[live] = en
        live = live[alive]
        if not live.size:
            break
    ok = np.linalg.norm(err(q, p, w), axis=1) < 1e-9
    return q, ok & np.all((q > np.array(arm.lower)) & (q < np.array(arm.upper)), axis=1)


def _schedule(rng, m: int, payloads, payload_kg) -> np.ndarray:
    if payload_kg is not None:
        return np.full(m, float(payload_kg))
    out, last = [], None
    while len(out) < m:
        kg = rng.choice([p for p in payloads if p != last])
        out += [float(kg)] * int(rng.integers(6, 16))
        last = kg
    return np.array(out[:m])


def plan(arm, jig: Jig | None = None, m: int = 120, seed: int = 0, cone_deg: float = 40.0,
         payloads=(0.0, 3.0, 6.0, 10.0), payload_kg: float | None = None, face_weights=None,
         standoff_m=(0.015, 0.04)) -> Searches:
    """m contacts on random face points (module docstring), in random order, taught on `arm` (the true arm: a
    user's program is taught on the robot, so each search starts `standoff_m` (15–40 mm) from its face along its
    direction); `face_weights` (one per jig face) how often each face is touched (default: alike)."""
    jig = jig or stepped_block()
    rng = np.random.default_rng(seed)
    starts = np.array([[0, 0.5, 0, 0, 0.8, 0], [0.5, 0.3, -0.3, 0, 1, 0], [-0.5, 0.3, -0.3, 0, 1, 0],
                       [0, 0.6, -0.6, 1.5, 1, 0], [0, 0.6, -0.6, -1.5, 1, 0], [0.3, 0.8, 0, 3, 0.5, 0]], float)
    lo, hi = np.array(arm.lower), np.array(arm.upper)
    parts: list[tuple] = []
    while sum(p[0].size for p in parts) < m:
        k = 2 * m
        fi = rng.choice(len(jig.faces), k, p=None if face_weights is None else np.asarray(face_weights) / np.sum(face_weights))
        P, N = points_on_faces(jig, fi, rng)

        def tilted(max_rad):
            ang = max_rad * np.sqrt(rng.uniform(0, 1, k))
            perp = np.cross(N, rng.normal(size=(k, 3)))
            perp /= np.linalg.norm(perp, axis=1, keepdims=True)
            return -np.cos(ang)[:, None] * N + np.sin(ang)[:, None] * perp  # into the face

        d = tilted(np.radians(cone_deg))
        w = tilted(np.radians(30))
        L = rng.uniform(*standoff_m, k)
        A = P - L[:, None] * d  # the search starts here and runs along d
        q, ok = np.zeros((k, 6)), np.zeros(k, bool)
        for s0 in starts:  # each start only where none before converged
            todo = np.flatnonzero(~ok)
            qq, good = _ik(arm, A[todo], w[todo], np.broadcast_to(s0, (todo.size, 6)).copy())
            q[todo[good]], ok[todo[good]] = qq[good], True
        J = jacobian6(arm, q)
        ok &= np.linalg.cond(J) < 300
        J[~ok] = np.eye(6)
        dq = np.linalg.solve(J, np.concatenate([d, np.zeros((k, 3))], axis=1)[..., None])[..., 0]
        u = rng.normal(size=(k, 3))
        u += (1.0 - np.sum(u * N, axis=1))[:, None] * N  # off the face, in a random direction
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        lift = np.linalg.solve(J, np.concatenate([u, np.zeros((k, 3))], axis=1)[..., None])[..., 0]
        via = q + rng.uniform(0.02, 0.06, k)[:, None] * lift
        ok &= np.all((via > lo) & (via < hi), axis=1) & np.all(np.abs(dq) < 20, axis=1)
        # the joint-space search line must stay near the straight one: at the stand-off it reaches the face point
        ok &= np.linalg.norm(tip(arm, q + L[:, None] * dq) - P, axis=1) < 1e-3
        idx = np.flatnonzero(ok)
        parts.append((fi[idx], q[idx], dq[idx], d[idx], via[idx]))
    face, q_a, dq, d, via = (np.concatenate([p[i] for p in parts])[:m] for i in range(5))
    speed = np.exp(rng.uniform(np.log(0.003), np.log(0.025), m))
    move = q_a - via
    overshoot = np.sign(move) * np.minimum(rng.uniform(0.5, 4.0, (m, 6)) * COUNT, 0.05 * np.abs(move))
    return Searches(face, q_a, dq, d, via, speed, overshoot, _schedule(rng, m, payloads, payload_kg))


def _settle(t: np.ndarray) -> np.ndarray:
    """The servo's residual after reaching a pose, per unit overshoot, t ≥ 0 s since arrival (its first peak ≈ 1)."""
    w = 2 * np.pi * OVERSHOOT_HZ
    t1 = np.arctan(w * OVERSHOOT_TAU) / w
    return np.exp(-t / OVERSHOOT_TAU) * np.sin(w * t) / (np.exp(-t1 / OVERSHOOT_TAU) * np.sin(w * t1))


def _turning_points(n_pts: int = 4) -> np.ndarray:
    """The settling residual's first extrema (per unit overshoot)."""
    w = 2 * np.pi * OVERSHOOT_HZ
    tk = (np.arctan(w * OVERSHOOT_TAU) + np.pi * np.arange(n_pts)) / w
    return _settle(tk)


def _cosine(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> np.ndarray:
    return a + (b - a) * (0.5 - 0.5 * np.cos(np.pi * np.clip(u, 0, 1)))[:, None]


def _more_joint_error(effects, q: np.ndarray) -> np.ndarray:
    """δq (n, 6) rad of this module's own joint forms (module docstring)."""
    dq = np.zeros_like(q)
    for e in effects:
        j, ph = e.where.get("joint", 1), e.where.get("phase", 0.7)
        if e.kind == "eccentricity":
            dq[:, j] += e.size * np.sin(q[:, j] + ph)
        elif e.kind == "transmission":
            dq[:, j] += e.size * np.sin(2 * q[:, j] + ph)
        elif e.kind == "scale":
            dq[:, j] += e.size * q[:, j]
        elif e.kind == "difference":  # δq_dst = k·(q_other − q_dst): an error in the relative angle
            other, dst = e.where["pair"]
            dq[:, dst] += e.size * (q[:, other] - q[:, dst])
    return dq


def _late(effects, speed: np.ndarray) -> np.ndarray:
    """Search travel (n,) m between the touch and the encoder's latch: latency × speed + pretravel."""
    out = np.zeros(speed.size)
    for e in effects:
        out += e.size * speed if e.kind == "latency" else e.size if e.kind == "pretravel" else 0.0
    return out


def _jig_shift(effects, face: np.ndarray, ax: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Where each touched face really is (n,) m along its axis, less its drawing: drift and face offsets."""
    out = np.zeros(face.size)
    for e in effects:
        if e.kind == "drift":
            out += np.where(ax == e.where.get("axis", 2), e.size * t, 0.0)
        elif e.kind == "face_offset":
            out += np.where(face == e.where["face"], e.size, 0.0)
    return out


def gear_play(sc: Searches, s: np.ndarray, width: float, j: int) -> np.ndarray:
    """δq_j (n,) = link − motor at each latch: joint j's motor path through the campaign (module docstring)
    through a dead band of `width` rad; `s` (n,) each search's travel to its latch (m)."""
    n = s.size
    tp = _turning_points()
    qa, via = sc.q_a[:n, j], sc.via[:n, j]
    latch = qa + s * sc.dq[:n, j]
    stop = latch + sc.speed[:n] * T_STOP * sc.dq[:n, j]
    out = np.empty(n)
    link = qa[0] - width / 2
    for i in range(n):
        for m in (via[i], *(qa[i] + sc.overshoot[i, j] * tp), qa[i]):
            link = min(max(link, m - width / 2), m + width / 2)
        link = min(max(link, latch[i] - width / 2), latch[i] + width / 2)
        out[i] = link - latch[i]
        for m in (stop[i], qa[i]):
            link = min(max(link, m - width / 2), m + width / 2)
    return out


def run(nominal, truth, sc: Searches, effects=(), seed: int = 0, n: int = 100, jig: Jig | None = None,
        repeatability_3sigma_m: float = 1e-4, jig_error_m: float = 2e-5, noise: float = 1.0,
        stream_noise_counts: float = 0.0) -> Campaign:
    """One campaign of the first n contacts of plan `sc` on the true arm with `effects` (`independent_touch`'s
    forms); `seed` draws the noise only (module docstring).  `stream_noise_counts`: the stream's readings (not
    the latches) carry that much Gaussian noise, in encoder counts (a servo's position estimate logged beside
    the hardware latch)."""
    jig = jig or stepped_block()
    rng = np.random.default_rng(seed)
    rows = np.arange(n)
    face, q_a, dq, speed, payload = sc.face[:n], sc.q_a[:n], sc.dq[:n], sc.speed[:n], sc.payload[:n]
    ax = np.array([jig.faces[f].axis_index for f in face])
    sg = np.array([jig.faces[f].normal_sign for f in face], float)
    other = np.array([jig.faces[f].other_axes() for f in face])
    coord = np.array([jig.faces[f].coordinate for f in face])
    ferr = noise * rng.uniform(-jig_error_m, jig_error_m, len(jig.faces))
    eps = noise * rng.normal(0, repeatability_3sigma_m / 3, (n, 3))
    qbar = np.mean(q_a, axis=0)
    lead = T_PTP + T_IN + T_SETTLE  # from the start of a cycle to the start of its search
    tail = T_STOP + T_DWELL + T_BACK

    def times(s):
        """Each latch's time (s from the stream's start)."""
        return np.cumsum(lead + s / speed + tail) - tail

    late = _late(effects, speed)  # the latch comes this much search travel after the touch

    def gap(s, ls, t):
        q = q_a + s[:, None] * dq
        dj = _joint_error(effects, q, qbar, lambda qq: gravity_torque(truth, qq, payload),
                          lambda width, j: gear_play(sc, s + late, width, j)) + _more_joint_error(effects, q)
        p = tip(truth, q + dj, ls) + eps
        c_true = (coord + ferr[face] + _face_shift(effects, face, p[rows[:, None], other], jig)
                  + _jig_shift(effects, face, ax, t))
        return sg * (p[rows, ax] - c_true)

    s = np.full(n, 0.03)
    for _ in range(3):  # the thermal growth depends on the contact time, which depends on s
        t = times(s + late)
        ls = _link_scale(effects, t)
        for _ in range(30):
            g = gap(s, ls, t)
            s = s - g / ((gap(s + 1e-6, ls, t) - g) / 1e-6)
        s = _bisect_unsettled(lambda ss: gap(ss, ls, t), s, travel_m=0.1)
    if np.max(np.abs(gap(s, ls, t))) > 1e-11:
        raise RuntimeError("contact search did not converge")
    s = s + late  # the encoder is latched here
    t_latch = times(s)
    q_latch = q_a + s[:, None] * dq
    if noise:
        q_latch = np.round(q_latch / COUNT) * COUNT
    t_stream, q_stream = _stream(sc, n, s, t_latch, rng if noise else None, stream_noise_counts * noise)
    t_ns = EPOCH_NS + np.round(t_stream * 1e9).astype(np.int64)
    tc_ns = EPOCH_NS + np.round(t_latch * 1e9).astype(np.int64)
    change = np.flatnonzero(np.r_[True, np.diff(payload) != 0])
    # each payload change is logged as the operator makes it, before the cycle's PTP move
    schedule = [{"t_ns": int(t_ns[0]) if k == 0 else int(tc_ns[i] - (lead + s[i] / speed[i]) * 1e9),
                 "payload_kg": float(payload[i])} for k, i in enumerate(change)]
    ids = np.array([jig.faces[f].id for f in face], object)
    contacts = {"timestamp_ns": tc_ns, "joint_positions": q_latch, "face": ids, "axis": ax, "coordinate": coord,
             "record": rows}
    sigma = float(np.hypot(repeatability_3sigma_m / 3, jig_error_m / np.sqrt(3))) * noise
    return Campaign(contacts, q_latch, sigma, speed, None, t_ns, q_stream,
                    [(d["t_ns"], d["payload_kg"]) for d in schedule], schedule, sc.direction[:n].copy(), payload,
                    {f.id: f.normal_sign for f in jig.faces})


def _stream(sc: Searches, n: int, s: np.ndarray, t_latch: np.ndarray, rng,
            noise_counts: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(t (k,) s, q (k, 6) rad) of the encoder stream: the motor path of the module docstring sampled at 250 Hz
    (with `rng`: timing jitter, dropped samples, `noise_counts` of reading noise and the encoder's quantisation)."""
    dt = 1 / RATE_HZ
    ts, qs = [], []
    prev = sc.q_a[0]
    for i in range(n):
        t_search = t_latch[i] - s[i] / sc.speed[i]
        t0 = t_search - T_SETTLE - T_IN - T_PTP
        u = np.arange(0, T_PTP, dt)
        qs.append(_cosine(prev, sc.via[i], u / T_PTP))
        ts.append(t0 + u)
        u = np.arange(0, T_IN, dt)
        qs.append(_cosine(sc.via[i], sc.q_a[i], u / T_IN))
        ts.append(t0 + T_PTP + u)
        u = np.arange(0, T_SETTLE, dt)
        qs.append(sc.q_a[i] + _settle(u)[:, None] * sc.overshoot[i])
        ts.append(t_search - T_SETTLE + u)
        u = np.arange(0, s[i] / sc.speed[i] + T_STOP, dt)
        qs.append(sc.q_a[i] + (np.minimum(u, s[i] / sc.speed[i] + T_STOP) * sc.speed[i])[:, None] * sc.dq[i])
        ts.append(t_search + u)
        stop = sc.q_a[i] + (s[i] + sc.speed[i] * T_STOP) * sc.dq[i]
        u = np.arange(0, T_DWELL + T_BACK, dt)
        qs.append(_cosine(stop, sc.q_a[i], (u - T_DWELL) / T_BACK))
        ts.append(t_latch[i] + T_STOP + u)
        prev = sc.q_a[i]
    t, q = np.concatenate(ts), np.concatenate(qs)
    o = np.argsort(t, kind="stable")
    t, q = t[o], q[o]
    keep = np.r_[True, np.diff(t) > 1e-6]
    t, q = t[keep], q[keep]
    if rng is not None:
        t = np.sort(t + rng.normal(0, 2e-4, t.size))
        keep = rng.uniform(size=t.size) > 0.003
        keep[0] = True
        q = q[keep] + rng.normal(0, noise_counts * COUNT, (keep.sum(), q.shape[1])) if noise_counts else q[keep]
        t, q = t[keep], np.round(q / COUNT) * COUNT
        keep = np.r_[True, np.diff(t) > 1e-6]
        t, q = t[keep], q[keep]
    return t, q
