"""Simulator of a laser-tracker calibration campaign of the Delta robot (seed 003).

The controller knows only the nominal model.  For each campaign point it:
  1. solves the nominal inverse kinematics for the commanded platform position;
  2. moves there in actuator space (smooth cosine profile) and settles;
  3. the tracker measures the reflector, whose true position follows from the *true* model
     (β' only, or the full model with axis-direction errors and unequal rods), in the tracker
     frame {T} placed somewhere on the floor, with Gaussian noise;
  4. the encoders are latched at the measurement.
Only what a real controller and tracker log reaches the recording; the truth goes to
TRUTH.json (both written by `pipeline.simulate.delta_recording`).  Defaults follow seed 003:
27 points on a 3×3×3 grid, Δx = Δy = 150 mm, Δz = 40 mm; tracker noise 0.02 mm (1σ per axis).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.errors import RobocalError
from pipeline.models import delta as dm
from pipeline.models.delta import Delta
from pipeline.simulate import thermal
from pipeline.systems.delta_tracker import H_NOMINAL, REG_KEYS, registration_matrix

EPOCH_NS = 1_767_225_600_000_000_000  # 2026-01-01T00:00:00Z
MM, DEG = 1e-3, np.pi / 180
TRUTH_MODELS = ("simplified", "full")


@dataclass(frozen=True)
class Noise:
    """Error sources; `scale` multiplies all (0 turns every one off, including quantisation)."""

    tracker_sigma_m: float = 2e-5  # 1σ per axis
    encoder_counts_per_rev: int = 2**17 * 50  # 17-bit motor encoder behind a 50:1 reducer
    scale: float = 1.0


@dataclass(frozen=True)
class Campaign:
    """What the integrator programs: a grid (seed 003) or `points` random points in its box."""

    grid: tuple[int, int, int] = (3, 3, 3)
    spacing_m: tuple[float, float, float] = (0.150, 0.150, 0.040)
    center_m: tuple[float, float, float] = (0.0, 0.0, -0.750)
    points: int | None = None
    seed: int = 0
    rate_hz: float = 250.0
    joint_speed_rad_s: float = 1.5
    settle_s: float = 0.5
    start_ns: int = EPOCH_NS
    targets_m: tuple | None = None  # explicit platform points ((x, y, z), …) in {A}, e.g. from a planned campaign


@dataclass(frozen=True)
class Truth:
    """True robot: error parameters (3 legs × (9 β' + 3 extended), flat, leg by leg),
    tracker registration (x, y, z, rz, ry, rx) and reflector offset h (m)."""

    beta: np.ndarray
    registration: np.ndarray
    h: float = H_NOMINAL
    model: str = "simplified"

    def parameters(self) -> dict[str, float]:
        names = dm.beta_names(3, extended=True) + list(REG_KEYS) + ["reflector.h"]
        return dict(zip(names, map(float, [*self.beta, *self.registration, self.h])))


def random_truth(rng: np.random.Generator, model: str = "simplified") -> Truth:
    """Errors of a well-built Delta: joints ±0.5 mm, actuator offsets 0.3°, links 0.3–0.5 mm;
    `full` adds axis direction errors (0.25°) and unequal parallelogram rods (0.2 mm).
    The tracker stands on the floor ~2 m from the robot, turned by ~35°."""
    if model not in TRUTH_MODELS:
        raise ValueError(f"unknown truth model {model!r} (use one of {TRUTH_MODELS})")
    B = np.zeros((3, 12))
    B[:, [0, 1, 2, 6, 7, 8]] = rng.normal(0, 0.5 * MM, (3, 6))
    B[:, 3] = rng.normal(0, 0.3 * DEG, 3)
    B[:, 4] = rng.normal(0, 0.3 * MM, 3)
    B[:, 5] = rng.normal(0, 0.5 * MM, 3)
    if model == "full":
        B[:, 9:11] = rng.normal(0, 0.25 * DEG, (3, 2))
        B[:, 11] = rng.normal(0, 0.2 * MM, 3)
    reg = np.array([1.6, -1.1, -1.4, 35 * DEG, 0, 0]) + np.concatenate(
        [rng.normal(0, 0.05, 3), rng.normal(0, [5 * DEG, 0.3 * DEG, 0.3 * DEG])])
    return Truth(beta=B.ravel(), registration=reg, h=H_NOMINAL, model=model)


def campaign_targets(c: Campaign) -> np.ndarray:
    """Commanded platform positions (n, 3) m in {A}: the grid visited layer by layer in a
    serpentine (consecutive points are neighbours), or uniform random points in its box."""
    if c.targets_m is not None:
        return np.asarray(c.targets_m, float).reshape(-1, 3)
    center, step, g = np.asarray(c.center_m), np.asarray(c.spacing_m), np.asarray(c.grid)
    half = (g - 1) / 2 * step
    if c.points is not None:
        rng = np.random.default_rng(c.seed + 7919)
        return center + rng.uniform(-half, half, (c.points, 3))
    rows = []
    for k in range(g[2]):
        for j in range(g[1]):
            jj = j if k % 2 == 0 else g[1] - 1 - j
            xs = range(g[0]) if (j + k * g[1]) % 2 == 0 else range(g[0] - 1, -1, -1)
            rows += [(i, jj, k) for i in xs]
    idx = np.array(rows, float)
    return center - half + idx * step


@dataclass
class SimResult:
    """A simulated campaign: what was logged, and the truth kept apart."""

    stream_t_ns: np.ndarray  # (T,) int64
    stream_q: np.ndarray  # (T, 3) rad
    t_ns: np.ndarray  # (n,) measurement times
    q: np.ndarray  # (n, 3) latched actuator angles, rad
    point_t: np.ndarray  # (n, 3) tracker readings, m in {T}
    targets: np.ndarray  # (n, 3) commanded positions, m in {A}
    tracker_noise: np.ndarray  # (n, 3) injected tracker noise, m
    measurement_error: np.ndarray  # (n, 3) reading (in {A}) minus true reflector at the latched angles, m
    point_index: np.ndarray | None = None  # (n,) commanded point of each measurement (None: 0..n-1)
    temperature: object = None  # simulate.thermal.Readings of /arm/temperature, when a sensor is logged

    @property
    def tracker_noise_rms_m(self) -> float:
        return float(np.sqrt(np.mean(self.tracker_noise**2)))

    @property
    def measurement_error_rms_m(self) -> float:
        return float(np.sqrt(np.mean(self.measurement_error**2)))


def true_reflector(delta: Delta, truth: Truth, theta: np.ndarray) -> np.ndarray:
    """True reflector position in {A} (n, 3) m: full-model forward kinematics."""
    p, R, ok = dm.full_forward(delta, truth.beta, theta, extended=True)
    if not np.all(ok):
        raise RobocalError(f"simulation: the true robot cannot assemble at {int((~ok).sum())} campaign points")
    return p + R @ np.array([0.0, 0.0, -truth.h])


def _quantise(q: np.ndarray, counts: int, on: bool) -> np.ndarray:
    if not on:
        return q
    step = 2 * np.pi / counts
    return np.round(q / step) * step


def commanded_angles(delta: Delta, campaign: Campaign) -> np.ndarray:
    """Actuator angles (n, 3) rad the controller commands for the campaign's points (nominal IK)."""
    targets = campaign_targets(campaign)
    theta, ok = dm.inverse(delta, np.zeros(27), targets)
    if not np.all(ok):
        bad = np.flatnonzero(~ok)
        raise RobocalError(f"simulation: {bad.size} campaign points are outside the nominal workspace "
                           f"(first: {targets[bad[0]].round(4).tolist()} m); shrink the grid or move its centre")
    return theta


def simulate(delta: Delta, truth: Truth, campaign: Campaign = Campaign(), noise: Noise = Noise()) -> SimResult:
    """Run a campaign (see module docstring).  Deterministic for a given `campaign.seed`."""
    rng = np.random.default_rng(campaign.seed)
    targets = campaign_targets(campaign)
    theta = commanded_angles(delta, campaign)
    k = noise.scale
    q_rec = _quantise(theta, noise.encoder_counts_per_rev, k > 0)
    M_true = true_reflector(delta, truth, theta)  # the actuators stand at the commanded angles
    R, t = registration_matrix(truth.registration)
    eps = rng.normal(0, k * noise.tracker_sigma_m, M_true.shape)
    point_t = (M_true - t) @ R + eps  # Rᵀ(M − t) + noise, row-wise
    err = (point_t @ R.T + t) - true_reflector(delta, truth, q_rec)
    t_ns, q_stream, t_meas = _timeline(theta, campaign)
    q_stream = _quantise(q_stream, noise.encoder_counts_per_rev, k > 0)
    return SimResult(stream_t_ns=t_ns, stream_q=q_stream, t_ns=t_meas, q=q_rec, point_t=point_t, targets=targets,
                     tracker_noise=eps, measurement_error=err)


def _timeline(theta: np.ndarray, c: Campaign):
    """Actuator trajectory sampled at the controller rate (cosine moves point to point, then
    a settle dwell; the tracker measures at the end of the dwell) and measurement times."""
    n = theta.shape[0]
    home = np.zeros(3)
    starts = np.concatenate([[home], theta[:-1]])
    move = np.max(np.abs(theta - starts), axis=1) / c.joint_speed_rad_s * 1.5 + 0.2
    # segments: move i, dwell i
    dur = np.empty(2 * n)
    dur[0::2], dur[1::2] = move, c.settle_s
    seg_start = np.empty((2 * n, 3))
    seg_end = np.empty((2 * n, 3))
    seg_start[0::2], seg_end[0::2] = starts, theta
    seg_start[1::2], seg_end[1::2] = theta, theta
    edges = np.concatenate([[0.0], np.cumsum(dur)])
    t_meas = c.start_ns + np.round(edges[2::2] * 1e9).astype(np.int64)
    T = np.arange(0.0, edges[-1] + 0.5 / c.rate_hz, 1.0 / c.rate_hz)
    seg = np.clip(np.searchsorted(edges, T, side="right") - 1, 0, 2 * n - 1)
    u = np.clip((T - edges[seg]) / dur[seg], 0, 1)
    wgt = 0.5 - 0.5 * np.cos(np.pi * u)
    q = seg_start[seg] + wgt[:, None] * (seg_end[seg] - seg_start[seg])
    return c.start_ns + np.round(T * 1e9).astype(np.int64), q, t_meas


# ----- concealed effects and campaign variations -----------------------------------------
EFFECTS = {  # name: (number of values, location kind)
    "backlash": (1, "actuator"), "actuator_scale": (1, "actuator"), "axis_yaw": (1, "leg"), "axis_tilt": (1, "leg"),
    "unequal_rods": (1, "leg"), "thermal_drift": (3, None), "tracker_scale": (1, None),
    "bump": (1, "actuator:centre"),  # out-of-library: a Gaussian bump in one actuator's transmission
}
BUMP_WIDTH_RAD = 0.05
# approach sides of (A1, A2, A3) per visit with --both-sides (balanced: no actuator's last-motion
# sign is tied to another's); each visit approaches from −pattern, then from +pattern
SIDE_PATTERNS = np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]])


@dataclass(frozen=True)
class Variations:
    """What the campaign varies to expose effects: each point approached from both sides of
    every actuator (via θ ∓ overshoot·pattern, the actuators' side patterns balanced over
    visits), `passes` over the point list (alternating order),
    a warm-up idle before the first point (s)."""

    both_sides: bool = False
    passes: int = 1
    warmup_s: float = 0.0
    overshoot_rad: float = 0.03
    warm_up: tuple[float, ...] = ()  # (τ s, ΔT∞ K): thermal_drift is then g·ΔT in m/K (simulate.thermal)
    temperature_sensor: bool = False  # log /arm/temperature


def check_effects(effects) -> None:
    """ValueError naming the problem for an unknown effect, wrong value count or location."""
    for e in effects:
        if e.name not in EFFECTS:
            raise ValueError(f"unknown delta-tracker effect {e.name!r} (use one of {', '.join(EFFECTS)})")
        nv, loc = EFFECTS[e.name]
        vals = e.values if e.name != "thermal_drift" or len(e.values) == 3 else None
        if vals is None or len(vals) != nv:
            raise ValueError(f"effect {e.label}: expected {nv} value(s), got {len(e.values)}")
        ok = (loc is None and e.location in (None, "campaign", "tracker")) or \
             (loc == "actuator" and e.location in ("A1", "A2", "A3")) or \
             (loc == "leg" and e.location in ("leg1", "leg2", "leg3")) or \
             (loc == "actuator:centre" and (e.location or "").partition(":")[0] in ("A1", "A2", "A3"))
        if not ok:
            where_ = {"actuator": "A1|A2|A3", "leg": "leg1|leg2|leg3", "actuator:centre": "A<i>:CENTRE_RAD"}.get(loc, "")
            raise ValueError(f"effect {e.label}: location must be {where_ or 'omitted'}")


def _via_timeline(waypoints: np.ndarray, measure: np.ndarray, c: Campaign, warmup_s: float, via_dwell_s: float = 0.1):
    """Cosine moves through `waypoints` (m, 3) rad from home after an idle `warmup_s`; a settle
    dwell after each measured waypoint (the tracker measures at its end), a short one after a
    via point.  Returns stream times, angles and the measurement times."""
    home = np.zeros(3)
    starts = np.concatenate([[home], waypoints[:-1]])
    move = np.max(np.abs(waypoints - starts), axis=1) / c.joint_speed_rad_s * 1.5 + 0.2
    dwell = np.where(measure, c.settle_s, via_dwell_s)
    dur = np.concatenate([[max(warmup_s, 0.0)], np.stack([move, dwell], 1).ravel()])
    seg_start = np.concatenate([[home], np.repeat(starts, 2, 0)])
    seg_end = np.concatenate([[home], np.repeat(waypoints, 2, 0)])
    seg_start[2::2] = waypoints  # dwell segments stand still
    dur = np.maximum(dur, 1e-9)
    edges = np.concatenate([[0.0], np.cumsum(dur)])
    t_meas = c.start_ns + np.round(edges[3::2][measure] * 1e9).astype(np.int64)
    T = np.arange(0.0, edges[-1] + 0.5 / c.rate_hz, 1.0 / c.rate_hz)
    seg = np.clip(np.searchsorted(edges, T, side="right") - 1, 0, dur.size - 1)
    u = np.clip((T - edges[seg]) / dur[seg], 0, 1)
    wgt = 0.5 - 0.5 * np.cos(np.pi * u)
    q = seg_start[seg] + wgt[:, None] * (seg_end[seg] - seg_start[seg])
    return c.start_ns + np.round(T * 1e9).astype(np.int64), q, t_meas


def simulate_effects(delta: Delta, truth: Truth, campaign: Campaign = Campaign(), noise: Noise = Noise(),
                     effects: tuple = (), variations: Variations = Variations()) -> SimResult:
    """A campaign with concealed effects in the TRUE robot/tracker (sign conventions of
    `pipeline.diagnose.adapters.delta`) and campaign variations.  Several effects may be combined."""
    from dataclasses import replace

    from pipeline.ingest.context import last_motion_sign

    check_effects(effects)
    rng = np.random.default_rng(campaign.seed)
    targets = campaign_targets(campaign)
    theta = commanded_angles(delta, campaign)
    v = variations
    order = np.concatenate([np.arange(len(theta)) if p % 2 == 0 else np.arange(len(theta))[::-1]
                            for p in range(max(1, v.passes))])
    way, meas, pidx = [], [], []
    for visit, i in enumerate(order):
        pattern = SIDE_PATTERNS[visit % len(SIDE_PATTERNS)]  # actuators' approach sides differ between visits
        for side in ((-1.0, 1.0) if v.both_sides else (None,)):
            if side is not None:
                way.append(theta[i] + side * pattern * v.overshoot_rad)
                meas.append(False)
            way.append(theta[i])
            meas.append(True)
            pidx.append(i)
    way, meas, pidx = np.array(way), np.array(meas), np.array(pidx)
    stream_t, q_stream, t_meas = _via_timeline(way, meas, campaign, v.warmup_s)
    cmd = way[meas]  # commanded angles at each measurement (the motors stand there)
    k = noise.scale
    q_rec = _quantise(cmd, noise.encoder_counts_per_rev, k > 0)
    sign = last_motion_sign(stream_t, q_stream, t_meas)
    t_s = (t_meas - stream_t[0]) * 1e-9
    B = truth.beta.reshape(3, 12).copy()
    dtheta = np.zeros_like(cmd)
    drift = np.zeros(3)
    scale = 0.0
    for e in effects:
        val = np.asarray(e.values, float)
        if e.name in ("backlash", "actuator_scale"):
            j = int(e.location[1]) - 1
            dtheta[:, j] += -0.5 * val[0] * sign[:, j] if e.name == "backlash" else val[0] * cmd[:, j]
        elif e.name == "bump":
            a, _, c0 = e.location.partition(":")
            j = int(a[1]) - 1
            dtheta[:, j] += val[0] * np.exp(-0.5 * ((cmd[:, j] - float(c0 or 0.0)) / BUMP_WIDTH_RAD) ** 2)
        elif e.name in ("axis_yaw", "axis_tilt"):
            B[int(e.location[3]) - 1, 9 if e.name == "axis_yaw" else 10] += val[0]
        elif e.name == "unequal_rods":
            B[int(e.location[3]) - 1, 11] += val[0]
        elif e.name == "thermal_drift":
            drift += val
        elif e.name == "tracker_scale":
            scale += val[0]
    true_ = replace(truth, beta=B.ravel())
    warm = thermal.WarmUp(*v.warm_up) if v.warm_up else None
    M_true = true_reflector(delta, true_, cmd + dtheta) + (t_s if warm is None else warm.rise(t_s))[:, None] * drift
    R, t = registration_matrix(truth.registration)
    eps = rng.normal(0, k * noise.tracker_sigma_m, M_true.shape)
    point_t = (1 + scale) * ((M_true - t) @ R) + eps
    err = eps @ R.T + (true_reflector(delta, true_, cmd) - true_reflector(delta, true_, q_rec))
    q_stream = _quantise(q_stream, noise.encoder_counts_per_rev, k > 0)
    sensor = replace(thermal.Sensor(), noise_k=thermal.Sensor().noise_k * k)
    temp = (thermal.read_sensor(warm, int(stream_t[0]), int(stream_t[-1]), np.random.default_rng([campaign.seed, 271828]),
                                sensor) if v.temperature_sensor else None)
    return SimResult(stream_t_ns=stream_t, stream_q=q_stream, t_ns=t_meas, q=q_rec, point_t=point_t,
                     targets=targets[pidx], tracker_noise=eps, measurement_error=err, point_index=pidx,
                     temperature=temp)


__all__ = ["Campaign", "Noise", "Truth", "Variations", "random_truth", "simulate", "simulate_effects", "field"]
