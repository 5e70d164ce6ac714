"""Simulator of seed 001's calibration campaign: the stripe is jogged onto rows of a printed
grid of 30 mm squares on the floor, and the crossings of the stripe with its corners are
picked in the image.

For each pose the operator (who sees the true image, so the *true* model decides):
  1. brings the scanner over the pattern: flange pose from a random aim point, stand-off
     (the stripe lands in the middle 60 % of the image), tilt up to 20° and wrist roll;
  2. jogs the arm (minimum-norm joint correction) until the laser stripe lies on the
     nearest grid line — a row, a column or a diagonal of the pattern;
  3. latches the encoders and picks `corners` crossings closest to the image centre.
Error sources: robot repeatability (the flange is not exactly where the encoders say),
target printing error (corners not exactly at their drawing coordinates) and image noise
(0.2 px).  Only what a real system logs reaches the recording; the truth goes to TRUTH.json.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from pipeline.models import camera as cam
from pipeline.models.serial_arm import SerialArm
from pipeline.models.transforms import rot
from pipeline.simulate.scanner_geometry import camera_pose as _camera_pose
from pipeline.simulate.scanner_geometry import floor_line as _floor_line
from pipeline.simulate.scanner_geometry import newton as _newton  # noqa: F401  (used by scanner_servo's callers)
from pipeline.simulate.scanner_geometry import project as _project
from pipeline.simulate.scanner_geometry import stripe_normal as _stripe_normal
from pipeline.simulate.scanner_operator import OperatorPose, backed_off_pose, draw_pose

EPOCH_NS = 1_767_225_600_000_000_000  # 2026-01-01T00:00:00Z


@dataclass(frozen=True)
class Noise:
    """Error sources; `scale` multiplies all (0 turns every one off)."""

    image_px: float = 0.2  # 1σ per pixel coordinate
    repeatability_3sigma_m: float = 2e-4  # SCORBOT-ER VII: ±0.2 mm
    print_sigma_m: float = 5e-5  # printed corner position, 1σ per in-plane axis
    scale: float = 1.0
    # Alternative repeatability mechanisms (0 = off, the default draws nothing extra), for
    # testing the diagnosis against error models other than the isotropic flange error above:
    joint_repeatability_rad: float = 0.0  # 1σ per joint: the arm stands at q + δq at the capture
    flange_anisotropy: tuple[float, float, float] = (1.0, 1.0, 1.0)  # per-{B}-axis factors on δt and δω
    encoder_repeatability_rad: float = 0.0  # 1σ per joint: the arm is where the stripe says, the encoders read δq off


@dataclass(frozen=True)
class Pattern:
    """Printed grid of squares lying on the floor z = z0 of the base frame (m)."""

    square_m: float = 0.030
    cols: int = 14  # squares along x
    rows: int = 10  # squares along y
    origin: tuple[float, float, float] = (0.29, -0.15, 0.0)

    def corners(self) -> np.ndarray:
        """(rows+1)*(cols+1) corner coordinates (m, base frame), row-major."""
        i, j = np.meshgrid(np.arange(self.cols + 1), np.arange(self.rows + 1))
        o = np.asarray(self.origin)
        return np.stack([o[0] + i.ravel() * self.square_m, o[1] + j.ravel() * self.square_m,
                         np.full(i.size, o[2])], axis=1)

    def ids(self) -> list[str]:
        return [f"r{j}c{i}" for j in range(self.rows + 1) for i in range(self.cols + 1)]

    def to_dict(self) -> dict:
        return {"kind": "printed_grid", "name": "30 mm squares on the floor", "square_m": self.square_m,
                "cols": self.cols, "rows": self.rows, "origin_m": list(self.origin),
                "frame": "robot base; corner r{j}c{i} = origin + (i, j, 0) * square_m"}


@dataclass(frozen=True)
class Campaign:
    """How the campaign is run."""

    poses: int = 5
    corners: int = 5
    seed: int = 0
    stripe_samples: int = 48
    rate_hz: float = 100.0
    joint_speed_rad_s: float = 0.5
    dwell_s: float = 1.0
    max_tilt_rad: float = np.radians(20)
    start_ns: int = EPOCH_NS
    capture_speed_rad_s: float = 0.0  # > 0: the arm sweeps through each pose while the image is captured
    spread: bool = False  # stripe rows over 10-90 % of the image and crossings spread along it (not the centre ones)


@dataclass
class Observation:
    """One latched pose: what the system logs (+ what only the simulator knows)."""

    q: np.ndarray  # (5,) encoder reading, rad
    corner_idx: np.ndarray  # (M,) pattern corner indices
    corner_px: np.ndarray  # (M,2) picked pixels
    stripe_px: np.ndarray  # (S,2) stripe profile pixels
    corner_true: np.ndarray  # (M,3) printed (true) corner positions


@dataclass
class SimResult:
    stream_t_ns: np.ndarray
    stream_q: np.ndarray
    obs_t_ns: np.ndarray
    observations: list[Observation]
    corner_error_rms_m: float
    attempts: int
    misses: tuple[int, ...] = ()  # planned poses (`simulate(..., planned=)`) that found no usable stripe


# ----- concealed effects ---------------------------------------------------------------------
EFFECTS = {  # name: (values, location kind) — conventions of `pipeline.diagnose.adapters.scanner`
    "tangential_distortion": (2, "camera"), "radial_k2": (1, "camera"), "time_offset": (1, "camera"),
    "stripe_peak_bias": (1, "camera"), "joint_offset": (1, "joint"), "joint_scale": (1, "joint"),
    "bump": (1, "joint:centre"),  # out-of-library: a Gaussian bump (rad) in one joint's transmission, J<i>:centre
}
BUMP_WIDTH_RAD = 0.1


def check_effects(effects, n_joints: int = 5) -> None:
    """ValueError naming the problem for an unknown effect, wrong value count or location."""
    joints = [f"J{i + 1}" for i in range(n_joints)]
    for e in effects:
        if e.name not in EFFECTS:
            raise ValueError(f"unknown scorbot-scanner effect {e.name!r} (use one of {', '.join(EFFECTS)})")
        nv, loc = EFFECTS[e.name]
        if len(e.values) != nv:
            raise ValueError(f"effect {e.label}: expected {nv} value(s), got {len(e.values)}")
        if loc == "joint:centre":
            j, _, c = (e.location or "").partition(":")
            try:
                float(c)
            except ValueError:
                j = None
            if j not in joints:
                raise ValueError(f"effect {e.label}: location must be J<i>:CENTRE (rad), e.g. J2:-0.5")
        elif (loc == "camera" and e.location not in (None, "camera")) or (loc == "joint" and e.location not in joints):
            raise ValueError(f"effect {e.label}: location must be {'|'.join(joints) if loc == 'joint' else 'omitted'}")


def effect_values(effects, n_joints: int = 5) -> dict:
    """Injected effects as arrays: k2 (1/m⁴), p1, p2 (1/m), peak_bias (px), time_offset (s),
    joint_offset (n_joints,) rad, joint_scale (n_joints,), bump [(joint index, amplitude rad, centre rad)]."""
    check_effects(effects, n_joints)
    fx = {"k2": 0.0, "p1": 0.0, "p2": 0.0, "peak_bias": 0.0, "time_offset": 0.0,
          "joint_offset": np.zeros(n_joints), "joint_scale": np.zeros(n_joints), "bump": []}
    for e in effects:
        v = [float(a) for a in e.values]
        if e.name == "tangential_distortion":
            fx["p1"] += v[0]
            fx["p2"] += v[1]
        elif e.name == "radial_k2":
            fx["k2"] += v[0]
        elif e.name == "stripe_peak_bias":
            fx["peak_bias"] += v[0]
        elif e.name == "time_offset":
            fx["time_offset"] += v[0]
        elif e.name == "bump":
            j, _, c = e.location.partition(":")
            fx["bump"].append((int(j[1:]) - 1, v[0], float(c)))
        else:
            fx[e.name][int(e.location[1:]) - 1] += v[0]
    return fx


def _bumps(fx: dict, q_enc: np.ndarray) -> np.ndarray:
    """Transmission bumps (rad) at encoder angles q_enc (n_joints,): true = enc + Σ A·exp(−½((enc − c)/w)²)."""
    out = np.zeros_like(q_enc)
    for j, a, c in fx["bump"]:
        out[j] += a * np.exp(-0.5 * ((q_enc[j] - c) / BUMP_WIDTH_RAD) ** 2)
    return out


def simulate(arm_nominal: SerialArm, arm_truth: SerialArm, scanner_truth: np.ndarray, campaign: Campaign = Campaign(),
             noise: Noise = Noise(), pattern: Pattern = Pattern(), image_size: tuple[int, int] = (640, 480),
             max_attempts: int = 400, effects: tuple = (), plan_cache: dict | None = None,
             planned: list[tuple[np.ndarray, np.ndarray, float]] | None = None) -> SimResult:
    """Run the campaign (module docstring).  Raises RuntimeError if the truth cannot see
    enough corners from reachable poses.  `effects` (`pipeline.simulate.effects.Injected`,
    names of `EFFECTS`) are injected into the TRUE camera/arm (`pipeline.diagnose.adapters.scanner`).
    `plan_cache` (a dict the caller keeps): the planned poses (the operator's IK, most of the
    time; the effects do not change them) memoised by the random generator's state before each
    plan — bit-identical results, several times faster when one campaign is re-simulated.
    `planned`: execute a planned campaign instead — per pose (joints rad, grid-line corner indices,
    image row px), servoed on the true arm (`scanner_servo`), or a first stage's `OperatorPose`
    (`scanner_operator.backed_off_pose`); the ones that fail are `misses`."""
    fx = effect_values(effects, arm_truth.n_joints)
    rng = np.random.default_rng(campaign.seed)
    s = np.asarray(scanner_truth, float)
    xa = arm_truth.vector()
    W, H = image_size
    k = noise.scale
    P_nom = pattern.corners()
    P_true = P_nom.copy()
    P_true[:, :2] += k * rng.normal(0, noise.print_sigma_m, (len(P_nom), 2))
    obs: list[Observation] = []
    attempts = 0
    used_lines: list[frozenset] = []
    sweeps: list[np.ndarray] = []
    queue = None if planned is None else list(enumerate(planned))
    misses: list[int] = []
    while (len(obs) < campaign.poses) if queue is None else queue:
        attempts += 1
        if queue is None and attempts > max_attempts:
            raise RuntimeError(f"could only place {len(obs)} of {campaign.poses} poses with {campaign.corners} "
                               f"visible corners")
        if queue is not None:
            from pipeline.simulate.scanner_servo import servo_pose

            i_plan, item = queue.pop(0)
            if isinstance(item, OperatorPose):  # a first-stage pose: the operator's, from the planned geometry
                plan = backed_off_pose(arm_nominal, xa, s, pattern, campaign, image_size, np.asarray(item.aim),
                                       item.standoff, item.tilt, item.roll)
            else:
                q0, line, row = item
                plan = servo_pose(arm_nominal.lower, arm_nominal.upper, xa, s, pattern, q0, line, row, image_size,
                                  campaign.corners)
            if plan is None:
                misses.append(i_plan)
                continue
        elif plan_cache is None:
            plan = draw_pose(arm_nominal, xa, s, pattern, campaign, rng, image_size)
        else:
            key = (xa.tobytes(), s.tobytes(), pattern, campaign, image_size, repr(rng.bit_generator.state))
            if key not in plan_cache:
                plan = draw_pose(arm_nominal, xa, s, pattern, campaign, rng, image_size)
                plan_cache[key] = (plan, rng.bit_generator.state)
            plan, state = plan_cache[key]
            rng.bit_generator.state = state
        if plan is None:
            continue
        q, idx = plan  # q: where the TRUE arm stands at the capture
        if queue is None and frozenset(idx.tolist()) in used_lines:
            continue
        w = np.zeros_like(q)
        if campaign.capture_speed_rad_s > 0:  # sweep direction of this pose (drawn only for moving captures)
            w = campaign.capture_speed_rad_s * rng.choice([-1.0, 1.0], q.size) * rng.uniform(0.5, 1.0, q.size)
        q_enc = q.copy()  # encoders: true = enc + offset + scale·enc, and the image is δ late
        for _ in range(8):
            q_enc = q - fx["joint_offset"] - fx["joint_scale"] * q_enc - w * fx["time_offset"] - _bumps(fx, q_enc)
        if noise.encoder_repeatability_rad:
            q_enc = q_enc + rng.normal(0, k * noise.encoder_repeatability_rad, q.size)
        # repeatability: the flange is not exactly where the encoders say
        sig = k * noise.repeatability_3sigma_m / 3
        ax, ay, az = noise.flange_anisotropy
        dR = rot("x", ax * rng.normal(0, sig / 0.3)) @ rot("y", ay * rng.normal(0, sig / 0.3)) \
            @ rot("z", az * rng.normal(0, sig / 0.3))
        dt = np.asarray(noise.flange_anisotropy) * rng.normal(0, sig, 3)
        q_cap = q + rng.normal(0, k * noise.joint_repeatability_rad, q.size) if noise.joint_repeatability_rad else q
        R_c, C = _camera_pose(xa, s, q_cap[None], (dR, dt))
        p0, dvec = _floor_line(R_c, C, s, pattern.origin[2])
        # the stripe point nearest each printed corner, seen through the actual camera
        X = P_true[idx]
        Y = p0 + ((X - p0) @ dvec[0])[:, None] * dvec
        Rn, Cn = np.repeat(R_c, len(idx), 0), np.repeat(C, len(idx), 0)
        px, _ = _project(Rn, Cn, s, Y, fx)
        nrm = _stripe_normal(px)
        px = px + fx["peak_bias"] * nrm + k * rng.normal(0, noise.image_px, px.shape)
        # stripe profile across the image
        t_c = (X - p0) @ dvec[0]
        ts = np.linspace(t_c.min() - 0.4, t_c.max() + 0.4, 4000)
        Ys = p0 + ts[:, None] * dvec
        Rs, Cs = np.repeat(R_c, ts.size, 0), np.repeat(C, ts.size, 0)
        spx, zs = _project(Rs, Cs, s, Ys, fx)
        spx = spx + fx["peak_bias"] * nrm
        vis = (zs > 0) & (spx[:, 0] >= 0) & (spx[:, 0] <= W - 1) & (spx[:, 1] >= 0) & (spx[:, 1] <= H - 1)
        spx = spx[vis]
        if len(spx) >= 2:
            spx = spx[np.linspace(0, len(spx) - 1, campaign.stripe_samples).round().astype(int)]
            spx = spx + k * rng.normal(0, noise.image_px, spx.shape)
        spx[:, 0] = np.clip(spx[:, 0], 0, W - 1)
        spx[:, 1] = np.clip(spx[:, 1], 0, H - 1)
        if np.any((px < 0) | (px > [W - 1, H - 1])):
            if queue is not None:
                misses.append(i_plan)
            continue
        used_lines.append(frozenset(idx.tolist()))
        obs.append(Observation(q=q_enc, corner_idx=idx, corner_px=px, stripe_px=spx, corner_true=X))
        sweeps.append(w)
    t_ns, q_stream, t_obs = _timeline(np.array([o.q for o in obs]), campaign, np.array(sweeps))
    err = np.concatenate([o.corner_true - P_nom[o.corner_idx] for o in obs])
    return SimResult(stream_t_ns=t_ns, stream_q=q_stream, obs_t_ns=t_obs, observations=obs,
                     corner_error_rms_m=float(np.sqrt(np.mean(np.sum(err**2, axis=1)))), attempts=attempts,
                     misses=tuple(misses))


def _timeline(Q: np.ndarray, c: Campaign, W: np.ndarray | None = None):
    """Encoder stream: home → each pose (cosine blend) → dwell; observation at mid-dwell.
    With sweep velocities W (N,5) rad/s the dwell is a constant-velocity sweep through the
    pose (q − W·dwell/2 → q + W·dwell/2), so the arm moves at W when the image is taken."""
    home = np.array([0.0, -0.4, 0.8, -0.4, 0.0])
    W = np.zeros_like(Q) if W is None or len(W) == 0 else W
    starts, ends, durs, lin = [], [], [], []
    prev = home
    for q, w in zip(Q, W):
        a, b = q - 0.5 * c.dwell_s * w, q + 0.5 * c.dwell_s * w
        move = float(np.max(np.abs(a - prev))) / c.joint_speed_rad_s * 1.5 + 0.5
        starts += [prev, a]
        ends += [a, b]
        durs += [move, c.dwell_s]
        lin += [False, True]
        prev = b
    starts, ends, durs, lin = np.array(starts), np.array(ends), np.array(durs), np.array(lin)
    edges = np.concatenate([[0.0], np.cumsum(durs)])
    T = np.arange(0.0, edges[-1], 1.0 / c.rate_hz)
    seg = np.clip(np.searchsorted(edges, T, side="right") - 1, 0, len(durs) - 1)
    u = np.clip((T - edges[seg]) / durs[seg], 0, 1)
    w = np.where(lin[seg], u, 0.5 - 0.5 * np.cos(np.pi * u))
    q = starts[seg] + w[:, None] * (ends[seg] - starts[seg])
    t_obs = c.start_ns + np.round((edges[1::2][:len(Q)] + 0.5 * c.dwell_s) * 1e9).astype(np.int64)
    return c.start_ns + np.round(T * 1e9).astype(np.int64), q, t_obs


def stripe_messages(sim: SimResult, pattern: Pattern) -> list[tuple[str, dict]]:
    """`/scanner/stripe` message bodies (drawing coordinates of the corners, never the truth)."""
    P, ids = pattern.corners(), pattern.ids()
    return [("/scanner/stripe", {"timestamp_ns": int(t), "joint_positions": o.q.tolist(),
                                 "stripe_px": o.stripe_px.tolist(), "corner_px": o.corner_px.tolist(),
                                 "corner_m": P[o.corner_idx].tolist(), "corner_ids": [ids[i] for i in o.corner_idx]})
            for t, o in zip(sim.obs_t_ns, sim.observations)]


def truth_document(arm_truth: SerialArm, scanner_truth: np.ndarray, noise: Noise, campaign: Campaign,
                   sim: SimResult, effects: tuple = ()) -> dict:
    """TRUTH.json (never written into the recording)."""
    from pipeline.systems.scorbot_scanner import gauge_invariants
    extra = {"effects": [{"effect": e.name, "location": e.location or "camera", "values": list(e.values)}
                         for e in effects]} if effects else {}
    return {"system": "scorbot-scanner", **extra,
            "scanner": {n: float(v) for n, v in zip(cam.SCANNER_NAMES, scanner_truth)},
            "scanner_invariants": gauge_invariants(scanner_truth),
            "arm": arm_truth.to_dict(), "noise": asdict(noise), "campaign": asdict(campaign),
            "corner_print_error_rms_m": sim.corner_error_rms_m, "planning_attempts": sim.attempts}


def simulate_in_memory(arm_nominal: SerialArm, arm_truth: SerialArm, scanner_truth: np.ndarray,
                       campaign: Campaign = Campaign(), noise: Noise = Noise(), pattern: Pattern = Pattern(),
                       effects: tuple = (), plan_cache: dict | None = None,
                       planned: list[tuple[np.ndarray, np.ndarray, float]] | None = None):
    """The measurement table a recording of this campaign would load to (for tests/benchmarks);
    with effects it also has timestamp_ns (the diagnosis rebuilds its context from the stream)."""
    sim = simulate(arm_nominal, arm_truth, scanner_truth, campaign, noise, pattern, effects=effects,
                   plan_cache=plan_cache, planned=planned)
    rows = [(i, o.q, px, pattern.corners()[j]) for i, o in enumerate(sim.observations)
            for px, j in zip(o.corner_px, o.corner_idx)]
    table = {"joint_positions": np.array([r[1] for r in rows]), "pixel": np.array([r[2] for r in rows]),
             "corner": np.array([r[3] for r in rows]), "pose": np.array([r[0] for r in rows]),
             "record": np.array([r[0] for r in rows]),
             "timestamp_ns": np.array([sim.obs_t_ns[r[0]] for r in rows], np.int64)}
    return sim, table
