"""An independent generator of touch campaigns for testing the diagnosis on data it did not make.

It shares NO code with the diagnosis's effect signatures nor with `pipeline.simulate`: its own
forward kinematics (a product of 4×4 homogeneous matrices, with its gravity torques and gear play in
`independent_arm`), its own inverse kinematics (damped
least squares on a finite-difference Jacobian), its own contact search (Newton on the gap along
a joint-space search line) and its own forms of every effect, several of them deliberately
outside the diagnosis's library:

- ``bump``:        δq_j = A·exp(−½((q_j − c)/w)²) in joint j's transmission;
- ``dent``:        a local bowl of depth D (m) and radius ρ on one face (the true face lies D·g(u, v)
                   inside the material, g a 2-D Gaussian of the position on the face);
- ``quad_coupling``: δq_3 = k·(q_2 − q̄_2)² (a nonlinear coupling of J3 on J2's angle; where["pair"] another
  (source, driven) pair of joint indices);
- ``thermal_growth``: a2 and d4 grow by α·L·(1 − e^(−t/τ)) (a warm-up acting through the kinematics);
  ``warm_up_all``: every D-H a, d grows so (the links that warm are all the links);
- ``wild``:        one contact latched `size` metres further along its search (a bad latch);
- ``glitch``:      J1's encoder stream reads `size` rad off over the 30 ms before one latch (the latch
                   itself is right; the approach speed derived from the stream is not);
- in-library forms: ``coupling`` δq_j = k·q_i (linear, default J2→J3), ``linear_growth`` every D-H a, d
  grows by α·L·t, ``backlash`` a dead band of b rad between motor (encoder) and link in joint j, run
  through the campaign's motor path (approach, search, retract: `play`; the link lags by b/2 behind the
  last motion that took up the play, a search shorter than the play leaves it where the approach did),
  ``compliance`` δq_j = c·τ_j (τ_j the gravity torque about joint j of the
  arm's lumped masses and the payload, computed here with this file's own kinematics).
`run(..., payload_kg=6.0)` makes a single-payload campaign (every contact with that payload).
A second campaign layout, `two_stations`: the stepped block and a copy of it shifted along x and down (J2 over a
wider range), the campaign change the diagnosis advises for a coupling it cannot tell from an eccentricity
(default offset: of the eight tried, the one whose J2→J3 coupling and J2 eccentricity signatures ⊥ the
geometry are furthest apart — principal angle 33° — a property of the campaign, not of any outcome).

The jig is this generator's own drawing of the stepped block (`independent_jig`).  A campaign is what a
controller logs: the contacts (time, latched joints, face, its axis and coordinate), the 250 Hz encoder stream,
the payload changes as they happened and each face's outward normal; the diagnosis table is built from them by
the product's recording-side code, as from a recording (`touch_ingest.diagnosis_table`) — nothing of robocal is
imported here.  Only `default_arms` reads the numbers of the nominal/true arm (base, D-H + Hayati joint terms,
tool, masses) from `pipeline.systems.arc_welder`, when called.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from independent_arm import (  # noqa: F401
    Arm,
    _rot,
    _trans,
    backlash_error,
    gravity_torque,
    play,
    pose,
    tip,
)

from independent_jig import Block as Jig
from independent_jig import shifted_copy, stepped_block  # noqa: F401

RATE_HZ = 250.0
COUNT = 2 * np.pi / 2**17
EPOCH_NS = 1_767_225_600_000_000_000


# ----- targets: own IK --------------------------------------------------------------------
def _ik(arm: Arm, p: np.ndarray, w: np.ndarray, q0: np.ndarray, iters: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """Damped least squares on [tip − p, wire − w] (wire = tool z); returns (q, converged)."""
    q = q0.copy()
    h = 1e-6

    def err(qq):
        T = pose(arm, qq)
        return np.concatenate([T[:, :3, 3] - p, 0.3 * (T[:, :3, 2] - w)], axis=1)

    for _ in range(iters):
        e = err(q)
        J = np.stack([(err(q + h * np.eye(6)[j]) - e) / h for j in range(6)], axis=2)
        JT = np.swapaxes(J, 1, 2)
        step = np.linalg.solve(JT @ J + 1e-6 * np.eye(6), JT @ e[..., None])[..., 0]
        q = q - np.clip(step, -0.3, 0.3)
    ok = np.linalg.norm(err(q), axis=1) < 1e-9
    ok &= np.all((q > np.array(arm.lower)) & (q < np.array(arm.upper)), axis=1)
    return q, ok


@dataclass
class Targets:
    face: np.ndarray  # (m,) face index
    q_a: np.ndarray  # (m, 6) approach pose
    dq: np.ndarray  # (m, 6) rad per m of search travel


def points_on_faces(jig, fi, rng) -> tuple[np.ndarray, np.ndarray]:
    """A point drawn uniformly on each face `fi[i]` of the jig, 1 cm inside its edges (k, 3) m, and that face's
    outward normal (k, 3), in the jig's frame."""
    k = len(fi)
    P, N = np.zeros((k, 3)), np.zeros((k, 3))
    for i, f in enumerate(fi):  # one face at a time, in the generator's draw order (its seeds' campaigns)
        fc = jig.faces[f]
        a, b = fc.other_axes()
        P[i, fc.axis_index] = fc.coordinate
        P[i, a] = rng.uniform(fc.extent[0][0] + 0.01, fc.extent[0][1] - 0.01)
        P[i, b] = rng.uniform(fc.extent[1][0] + 0.01, fc.extent[1][1] - 0.01)
        N[i, fc.axis_index] = fc.normal_sign
    return P, N


def plan(nominal: Arm, jig: Jig, m: int = 160, seed: int = 0, offset: float = 0.04) -> Targets:
    """m approach poses, `offset` off random points of the faces, wire tilted ≤ 30° off the normal."""
    rng = np.random.default_rng(seed)
    faces, Q, DQ = [], [], []
    seeds = np.array([[0, 0.5, 0, 0, 0.8, 0], [0.5, 0.3, -0.3, 0, 1, 0], [-0.5, 0.3, -0.3, 0, 1, 0],
                      [0, 0.6, -0.6, 1.5, 1, 0], [0, 0.6, -0.6, -1.5, 1, 0], [0.3, 0.8, 0, 3, 0.5, 0]], float)
    while sum(len(f) for f in faces) < m:
        k = 4 * m
        fi = rng.integers(0, len(jig.faces), k)
        P, N = points_on_faces(jig, fi, rng)
        tilt = np.radians(30) * np.sqrt(rng.uniform(0, 1, k))
        perp = np.cross(N, rng.normal(size=(k, 3)))
        perp /= np.linalg.norm(perp, axis=1, keepdims=True)
        w = -np.cos(tilt)[:, None] * N + np.sin(tilt)[:, None] * perp  # the wire points into the face
        best_q, best_ok = np.zeros((k, 6)), np.zeros(k, bool)
        for s0 in seeds:
            q, ok = _ik(nominal, P + offset * N, w, np.broadcast_to(s0, (k, 6)).copy())
            new = ok & ~best_ok
            best_q[new] = q[new]
            best_ok |= ok
        idx = np.flatnonzero(best_ok)
        q_a = best_q[idx]
        h = 1e-6
        p0 = tip(nominal, q_a)
        Jp = np.stack([(tip(nominal, q_a + h * np.eye(6)[j]) - p0) / h for j in range(6)], axis=2)
        # minimum-norm joint rate moving the tip along −n at unit speed
        dq = np.einsum("nij,nj->ni", np.linalg.pinv(Jp), -N[idx])
        faces.append(fi[idx])
        Q.append(q_a)
        DQ.append(dq)
    return Targets(np.concatenate(faces)[:m], np.concatenate(Q)[:m], np.concatenate(DQ)[:m])


# ----- effects (own forms) ----------------------------------------------------------------
@dataclass(frozen=True)
class Effect:
    kind: str  # bump | dent | quad_coupling | thermal_growth | warm_up_all | wild | glitch | coupling | linear_growth
    # | backlash | compliance
    size: float
    where: dict = field(default_factory=dict)


def _joint_error(effects, q: np.ndarray, qbar: np.ndarray, torque=None, backlash=None) -> np.ndarray:
    """δq (n, 6) rad: `torque(q)` the gravity torques, `backlash(width, j)` joint j's play at each latch."""
    dq = np.zeros_like(q)
    for e in effects:
        if e.kind == "backlash":  # the load lags the motor through the play
            j = e.where.get("joint", 0)
            dq[:, j] += backlash(e.size, j)
        elif e.kind == "compliance":
            j = e.where.get("joint", 1)
            dq[:, j] += e.size * torque(q)[:, j]
        if e.kind == "bump":
            j = e.where.get("joint", 1)
            dq[:, j] += e.size * np.exp(-0.5 * ((q[:, j] - e.where["centre"]) / e.where.get("width", 0.1)) ** 2)
        elif e.kind == "quad_coupling":  # δq_dst = k·(q_src − q̄_src)² (default J2 -> J3)
            src, dst = e.where.get("pair", (1, 2))
            dq[:, dst] += e.size * (q[:, src] - qbar[src]) ** 2
        elif e.kind == "coupling":  # δq_dst = k·q_src (default J2 -> J3)
            src, dst = e.where.get("pair", (1, 2))
            dq[:, dst] += e.size * q[:, src]
    return dq


def _link_scale(effects, t: np.ndarray) -> np.ndarray | None:
    """thermal_growth: (a2, d4) scale (n, 2); linear_growth, warm_up_all: every a and d (n, 6)."""
    for e in effects:
        if e.kind == "thermal_growth":
            return 1 + e.size * np.repeat((1 - np.exp(-t / e.where.get("tau_s", 600.0)))[:, None], 2, axis=1)
        if e.kind == "warm_up_all":
            return 1 + e.size * np.repeat((1 - np.exp(-t / e.where.get("tau_s", 600.0)))[:, None], 6, axis=1)
        if e.kind == "linear_growth":
            return 1 + e.size * np.repeat(t[:, None], 6, axis=1)
    return None


def _face_shift(effects, face_idx: np.ndarray, uv: np.ndarray, jig: Jig) -> np.ndarray:
    """Displacement of the true face along its axis (m) at each contact's position on it."""
    out = np.zeros(face_idx.size)
    for e in effects:
        if e.kind == "dent":
            f = e.where["face"]
            on = face_idx == f
            g = np.exp(-0.5 * np.sum((uv - np.asarray(e.where["centre"])) ** 2, axis=1) / e.where["radius"] ** 2)
            out[on] -= jig.faces[f].normal_sign * e.size * g[on]  # into the material
    return out


def _bisect_unsettled(gap, s: np.ndarray, travel_m: float = 0.12, step_m: float = 1e-3, tol: float = 1e-11) -> np.ndarray:
    """Where Newton did not settle (a gap with a kink, a search line that curves), the first zero of the gap
    along the search: bracketed on a `step_m` grid up to `travel_m`, then bisected.  Rows that settled stay
    where they are (a dead band couples each contact to the one before); a row with no crossing stays as it
    was (the caller refuses it)."""
    g = gap(np.nan_to_num(s, nan=0.0))
    bad = ~(np.abs(g) <= tol)
    if not bad.any():
        return s
    base = np.where(bad, 0.0, s)
    lo, hi = np.zeros_like(s), np.full_like(s, np.nan)
    for v in np.arange(0.0, travel_m + step_m, step_m):
        cross = bad & np.isnan(hi) & (gap(np.where(bad, v, base)) <= 0)
        hi = np.where(cross, v, hi)
        lo = np.where(bad & np.isnan(hi), v, lo)
    found = bad & ~np.isnan(hi)
    hi = np.where(found, hi, lo)
    for _ in range(60):
        mid = np.where(found, 0.5 * (lo + hi), base)
        below = gap(mid) <= 0
        hi, lo = np.where(below, mid, hi), np.where(below, lo, mid)
    return np.where(found, 0.5 * (lo + hi), s)


# ----- campaign ---------------------------------------------------------------------------
@dataclass
class Campaign:
    contacts: dict  # what the controller logged per contact: timestamp_ns, joint_positions, face, axis, coordinate,
    # record (the diagnosis table is built from it, the stream and the payload changes: `touch_ingest`)
    truth_joint_q: np.ndarray  # (n, 6) encoder-latched q
    along_normal_noise_sigma_m: float
    search_speed: np.ndarray
    wild_record: int | None = None
    # what a controller logs beside the contacts (for `write_recording`)
    stream_t_ns: np.ndarray | None = None
    stream_q: np.ndarray | None = None
    payload_changes: list = field(default_factory=list)  # [(t_ns, kg)] when the payload actually changed
    planned_schedule: list = field(default_factory=list)  # the campaign's programmed schedule
    search_direction: np.ndarray | None = None  # (n, 3) unit, into the face
    payload_kg: np.ndarray | None = None  # (n,) the payload each contact was really made with (this generator's own)
    normal_sign_of: dict = field(default_factory=dict)  # face id → its outward normal's sign along its axis


def run(nominal: Arm, truth: Arm, targets: Targets, effects=(), seed: int = 0, n: int = 100,
        jig: Jig | None = None, repeatability_3sigma_m: float = 1e-4, jig_error_m: float = 2e-5,
        noise: float = 1.0, payload_late: int = 0, payload_kg: float | None = None) -> Campaign:
    """One campaign of n contacts on the first touching targets: payload 0/6 kg in blocks of 10
    (`payload_kg`: that payload for every contact), search speeds 5/10/20 mm/s, the true robot with
    `effects` (its own forms).  `payload_late`: the operator changes the payload this many contacts
    after the programmed block boundary (the table then follows the changes as they happened)."""
    jig = jig or stepped_block()
    rng = np.random.default_rng(seed)
    idx = np.arange(n)
    face = targets.face[idx]
    q_a, dq = targets.q_a[idx], targets.dq[idx]
    ax = np.array([jig.faces[f].axis_index for f in face])
    sg = np.array([jig.faces[f].normal_sign for f in face], float)
    other = np.array([jig.faces[f].other_axes() for f in face])
    coord = np.array([jig.faces[f].coordinate for f in face])
    ferr = noise * rng.uniform(-jig_error_m, jig_error_m, len(jig.faces))
    eps = noise * rng.normal(0, repeatability_3sigma_m / 3, (n, 3))
    speed = rng.choice([0.005, 0.01, 0.02], n)
    qbar = np.mean(q_a, axis=0)
    rows = np.arange(n)
    planned = np.where((rows // 10) % 2 == 1, 6.0, 0.0) if payload_kg is None else np.full(n, float(payload_kg))
    payload = (np.where((np.maximum(rows - payload_late, 0) // 10) % 2 == 1, 6.0, 0.0) if payload_kg is None
               else planned.copy())
    extra = np.zeros(n)  # a late latch: travel past the contact (m)
    wild = None
    for e in effects:
        if e.kind == "wild":
            wild = int(e.where.get("record", n // 2))
            extra[wild] += e.size

    def times(s):
        """Contact times (s): each cycle is a 2 s move, 0.3 s settle, the search, 1.2 s dwell + retract."""
        return 5.0 + np.cumsum(2.0 + 0.3 + (s + extra) / speed + 1.2) - 1.2 - extra / speed  # physical contact

    def gap(s, ls):
        q = q_a + s[:, None] * dq
        dj = _joint_error(effects, q, qbar, lambda qq: gravity_torque(truth, qq, payload),
                          lambda width, j: backlash_error(q_a, dq, s, width, j))
        p = tip(truth, q + dj, ls) + eps
        uv = p[rows[:, None], other]
        c_true = coord + ferr[face] + _face_shift(effects, face, uv, jig)
        return sg * (p[rows, ax] - c_true)

    s = np.full(n, 0.04)
    for _ in range(3):  # the thermal growth depends on the contact time, which depends on s
        ls = _link_scale(effects, times(s))
        for _ in range(30):
            g = gap(s, ls)
            s = s - g / ((gap(s + 1e-6, ls) - g) / 1e-6)
        s = _bisect_unsettled(lambda ss: gap(ss, ls), s)
    if np.max(np.abs(gap(s, ls))) > 1e-11:
        raise RuntimeError("contact search did not converge")
    t_contact = times(s) + extra / speed  # the latch
    s = s + extra
    q_latch = q_a + s[:, None] * dq
    if noise:
        q_latch = np.round(q_latch / COUNT) * COUNT
    # encoder stream: move from the previous retract pose to q_a (cosine profile, 2 s), search at
    # constant speed to the latch, dwell, retract to q_a (1 s)
    ts, qs = [], []
    prev = q_a[0]
    t0 = 0.0
    dt = 1 / RATE_HZ
    for i in range(n):
        tm = np.arange(0, 2.0, dt)
        qs.append(prev + (q_a[i] - prev) * (0.5 - 0.5 * np.cos(np.pi * tm / 2.0))[:, None])
        ts.append(t0 + tm)
        t_s = t_contact[i] - s[i] / speed[i]  # search start
        tsr = np.arange(t_s, t_contact[i], dt)
        qs.append(q_a[i] + ((tsr - t_s) * speed[i])[:, None] * dq[i])
        ts.append(tsr)
        td = np.arange(t_contact[i], t_contact[i] + 1.2, dt)
        back = np.clip((td - t_contact[i] - 0.2) / 1.0, 0, 1)
        qs.append(q_latch[i] + back[:, None] * (q_a[i] - q_latch[i]))
        ts.append(td)
        prev, t0 = q_a[i], t_contact[i] + 1.2
    t_stream = np.concatenate(ts)
    q_stream = np.concatenate(qs)
    for e in effects:  # an encoder glitch: J1 reads `size` rad off over the 30 ms before one latch
        if e.kind == "glitch":
            i = int(e.where.get("record", n // 2))
            hit = (t_stream >= t_contact[i] - 0.03) & (t_stream < t_contact[i])
            q_stream[hit, 0] += e.size
    o = np.argsort(t_stream, kind="stable")
    t_stream, q_stream = t_stream[o], q_stream[o]
    keep = np.r_[True, np.diff(t_stream) > 1e-6]
    t_stream, q_stream = t_stream[keep], q_stream[keep]
    if noise:
        q_stream = np.round(q_stream / COUNT) * COUNT
    t_ns = EPOCH_NS + np.round(t_stream * 1e9).astype(np.int64)
    tc_ns = EPOCH_NS + np.round(t_contact * 1e9).astype(np.int64)
    change = np.flatnonzero(np.r_[True, np.diff(payload) != 0])
    schedule = [{"t_ns": int(tc_ns[i] - 3e9), "payload_kg": float(payload[i])} for i in change]
    schedule[0]["t_ns"] = int(t_ns[0])
    p_change = np.flatnonzero(np.r_[True, np.diff(planned) != 0])
    planned_schedule = [{"t_ns": int(t_ns[0]) if k == 0 else int(tc_ns[i] - 3e9), "payload_kg": float(planned[i])}
                        for k, i in enumerate(p_change)]
    ids = np.array([jig.faces[f].id for f in face], object)
    contacts = {"timestamp_ns": tc_ns, "joint_positions": q_latch, "face": ids, "axis": ax, "coordinate": coord,
             "record": rows}
    direction = np.zeros((n, 3))
    direction[rows, ax] = -sg
    return Campaign(contacts, q_latch, float(np.hypot(repeatability_3sigma_m / 3, jig_error_m / np.sqrt(3))) * noise,
                    speed, wild, t_ns, q_stream, [(d["t_ns"], d["payload_kg"]) for d in schedule], planned_schedule,
                    direction, payload, {f.id: f.normal_sign for f in jig.faces})


# ----- minimum detectable size, computed here (3σ over the projected signature) --------------
def geometric_jacobian(arm: Arm, q: np.ndarray, ax: np.ndarray) -> np.ndarray:
    """(n, 42) ∂(tip along the measured axis)/∂(base, joint, tool terms), finite differences."""
    base, joints, tool = np.array(arm.base), np.array(arm.joints), np.array(arm.tool)
    v0 = np.concatenate([base, joints.ravel(), tool])
    rows = np.arange(q.shape[0])

    def f(v):
        a = Arm(tuple(v[:6]), tuple(map(tuple, v[6:36].reshape(6, 5))), tuple(v[36:]), arm.lower, arm.upper)
        return tip(a, q)[rows, ax]

    f0 = f(v0)
    h = 1e-7
    return np.stack([(f(v0 + h * np.eye(v0.size)[i]) - f0) / h for i in range(v0.size)], axis=1)


_CLEAN: list = []  # the last few noise-free, effect-free campaigns: (inputs, campaign)


def _clean(runner, nominal, truth, targets, n, jig, campaign):
    """`runner`'s noise-free campaign without effects, kept for the same inputs (the same objects): every
    signature on one plan starts from it."""
    key = (runner, nominal, truth, n, jig, tuple(sorted(campaign.items())))
    for (t, k), c in _CLEAN:
        try:
            if t is targets and k == key:
                return c
        except ValueError:  # array-valued options: not compared
            pass
    c = runner(nominal, truth, targets, (), seed=0, n=n, jig=jig, noise=0.0, **campaign)
    _CLEAN.append(((targets, key), c))
    del _CLEAN[:-4]
    return c


def signature(nominal: Arm, truth: Arm, targets: Targets, effect: Effect, n: int = 100, jig: Jig | None = None, *,
              at_size: bool = False, runner=None, **campaign) -> tuple[np.ndarray, np.ndarray]:
    """(S (n,) m per unit of the effect, J (n, 42) the geometric Jacobian): the change of each contact's residual
    (the model tip at the latched q, along the measured axis) per unit effect, the tangent at 10⁻³ × the
    effect's size or (`at_size`) the secant at its size, noise-free; `runner` the campaign's `run` (default this
    module's; `independent_search.run` for its plans), `campaign` its options."""
    jig = jig or stepped_block()
    runner = runner or run
    c0 = _clean(runner, nominal, truth, targets, n, jig, campaign)
    unit = effect if at_size else Effect(effect.kind, 1e-3 * (effect.size or 1.0), effect.where)
    c1 = runner(nominal, truth, targets, (unit,), seed=0, n=n, jig=jig, noise=0.0, **campaign)
    ax = c0.contacts["axis"]
    rows = np.arange(ax.size)
    # residual change: the same coordinates, the model tip at the latched q moves
    r0 = tip(truth, c0.truth_joint_q)[rows, ax]
    r1 = tip(truth, c1.truth_joint_q)[rows, ax]
    return (r1 - r0) / unit.size, geometric_jacobian(truth, c0.truth_joint_q, ax)


def mds(nominal: Arm, truth: Arm, targets: Targets, effect: Effect, sigma: float, n: int = 100,
        jig: Jig | None = None, *, at_size: bool = False, drop_top: int = 0, runner=None, **campaign) -> float:
    """3σ / ‖signature ⊥ geometry‖: the effect size (in its own unit) just detectable (`campaign`: `run`'s
    options, e.g. payload_kg), the signature of `signature` (a dead band's shape changes with its play: a
    search shorter than the play does not turn the link, so `at_size` takes the secant at the effect's size).
    `drop_top` contacts carrying the largest shares of the ⊥ signature are left out, one at a time and
    re-projected: the figure for a test that must not rest on those few contacts."""
    return mds_dropping(nominal, truth, targets, effect, sigma, n, jig, at_size=at_size, upto=drop_top,
                        runner=runner, **campaign)[-1]


def mds_dropping(nominal: Arm, truth: Arm, targets: Targets, effect: Effect, sigma: float, n: int = 100,
                 jig: Jig | None = None, *, at_size: bool = False, upto: int = 0, runner=None,
                 **campaign) -> list[float]:
    """`mds` with 0, 1, …, `upto` top contacts left out, from one signature: [m₀, m₁, …]."""
    S, J = signature(nominal, truth, targets, effect, n, jig, at_size=at_size, runner=runner, **campaign)
    keep = np.ones(S.size, bool)
    out = []
    for k in range(upto + 1):
        U, sv, _ = np.linalg.svd(J[keep], full_matrices=False)
        U = U[:, sv > sv[0] * 1e-9]
        Sp = S[keep] - U @ (U.T @ S[keep])
        out.append(3 * sigma / max(np.linalg.norm(Sp), 1e-300))
        if k < upto:
            keep[np.flatnonzero(keep)[np.argmax(Sp**2)]] = False
    return out


def two_stations(dx: float = 0.45, dz: float = -0.35) -> Jig:
    """The stepped block and a copy of it shifted by `dx` along the jig's x and `dz` along its z (m; faces `s_…`):
    a second station that takes J2 (and J3) over other combinations than the block alone."""
    return shifted_copy(stepped_block(), dx, dz)


def default_arms() -> tuple[Arm, Arm]:
    """(nominal, true) arm: the numbers of robocal's arc-welder system (its nominal arm and the reference truth),
    read when called — numbers only; every computation on them is this generator's own."""
    from pipeline.systems import arc_welder as aw

    return Arm.of(aw.nominal_arm()), Arm.of(aw.reference_truth())
