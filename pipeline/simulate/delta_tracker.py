"""Simulator of a laser-tracker calibration campaign of the Delta robot (seed 003).

The controller knows only the nominal model.  For each campaign point it:
  1. solves the nominal inverse kinematics for the commanded platform position;
  2. moves there in actuator space (smooth cosine profile) and settles;
  3. the tracker measures the reflector, whose true position follows from the *true* model
     (β' only, or the full model with axis-direction errors and unequal rods), in the tracker
     frame {T} placed somewhere on the floor, with Gaussian noise;
  4. the encoders are latched at the measurement.
Only what a real controller and tracker log reaches the recording; the truth goes to
TRUTH.json.  Defaults follow seed 003: 27 points on a 3×3×3 grid, Δx = Δy = 150 mm,
Δz = 40 mm; tracker noise 0.02 mm (1σ per axis).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from pipeline.errors import RobocalError
from pipeline.models import delta as dm
from pipeline.models.delta import Delta
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


def simulate(delta: Delta, truth: Truth, campaign: Campaign = Campaign(), noise: Noise = Noise()) -> SimResult:
    """Run a campaign (see module docstring).  Deterministic for a given `campaign.seed`."""
    rng = np.random.default_rng(campaign.seed)
    targets = campaign_targets(campaign)
    theta, ok = dm.inverse(delta, np.zeros(27), targets)
    if not np.all(ok):
        bad = np.flatnonzero(~ok)
        raise RobocalError(f"simulation: {bad.size} campaign points are outside the nominal workspace "
                           f"(first: {targets[bad[0]].round(4).tolist()} m); shrink the grid or move its centre")
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


def tracker_messages(sim: SimResult) -> list[tuple[str, dict]]:
    """`/tracker/point` message bodies of a simulated campaign."""
    return [("/tracker/point", {"timestamp_ns": int(t), "joint_positions": q, "point": p, "point_index": i})
            for i, (t, q, p) in enumerate(zip(sim.t_ns, np.round(sim.q, 12).tolist(), sim.point_t.tolist()))]


def truth_document(delta: Delta, truth: Truth, noise: Noise, campaign: Campaign, sim: SimResult) -> dict:
    """TRUTH.json: true parameters and realised errors (never written to the recording)."""
    return {
        "system": "delta-tracker",
        "truth_model": truth.model,
        "nominal": delta.to_dict(),
        "parameters": truth.parameters(),
        "noise": asdict(noise),
        "campaign": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(campaign).items()},
        "tracker_noise_rms_m": sim.tracker_noise_rms_m,
        "measurement_error_rms_m": sim.measurement_error_rms_m,
        "note": "tracker_noise_rms_m: injected tracker noise per axis; measurement_error_rms_m: the whole error "
                "a perfect model would leave (tracker noise plus encoder quantisation), per axis",
    }


def recording_metadata(delta: Delta, campaign: Campaign, noise: Noise) -> dict[str, dict]:
    """Metadata records of a campaign: nominal robot, tracker/reflector fixture, campaign plan."""
    from pipeline.recording.schemas import META_CAMPAIGN, META_FIXTURE, META_ROBOT

    return {
        META_ROBOT: delta.to_dict(),
        META_FIXTURE: {"kind": "laser_tracker", "reflector_offset_m": H_NOMINAL,
                       "note": "reflector (SMR centre) sits reflector_offset_m below the platform point P "
                               "along the platform's w axis (seed 003 eq. 13)"},
        META_CAMPAIGN: {"system": "delta-tracker", "simulated": True,
                        "grid": list(campaign.grid), "spacing_m": list(campaign.spacing_m),
                        "center_m": list(campaign.center_m), "random_points": campaign.points,
                        "controller_rate_hz": campaign.rate_hz, "settle_s": campaign.settle_s,
                        "tracker_sigma_m": noise.tracker_sigma_m * noise.scale},
    }


def write(path, delta: Delta, truth: Truth, campaign: Campaign = Campaign(), noise: Noise = Noise(),
          truth_path=None) -> SimResult:
    """Simulate and write REC.mcap (and TRUTH.json if `truth_path`)."""
    import json
    from pathlib import Path

    from pipeline.recording.writer import write_campaign

    sim = simulate(delta, truth, campaign, noise)
    write_campaign(path, recording_metadata(delta, campaign, noise), (sim.stream_t_ns, sim.stream_q, ["A1", "A2", "A3"]),
                   tracker_messages(sim))
    if truth_path is not None:
        Path(truth_path).write_text(json.dumps(truth_document(delta, truth, noise, campaign, sim), indent=2) + "\n")
    return sim


__all__ = ["Campaign", "Noise", "Truth", "random_truth", "simulate", "write", "truth_document", "field"]
