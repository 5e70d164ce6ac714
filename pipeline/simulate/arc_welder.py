"""Simulator of a touch-sensing campaign (seed 000), run the way the robot would run it.

For each target on a jig face the controller, which only knows the *nominal* model:
  1. solves the nominal inverse kinematics for an approach pose `approach_offset_m` off the
     face, wire tilted up to 30° from the face normal;
  2. moves there point-to-point (joint space, smooth cosine velocity profile);
  3. searches slowly along the nominal face normal until the wire touches the face — the
     contact is decided by the *true* model, the robot's repeatability error and the true
     (machined) face position — and latches the encoders;
  4. retracts to the approach pose.
The encoder stream is sampled at the controller rate throughout.  Targets whose true
contact would fall off the face (the wire misses it) are dropped and replaced, as a real
search would report "no contact".  Only what a real controller logs reaches the recording.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from pipeline.models import ik, serial_arm
from pipeline.models.jig import Jig
from pipeline.models.serial_arm import SerialArm
from pipeline.models.transforms import rot

EPOCH_NS = 1_767_225_600_000_000_000  # 2026-01-01T00:00:00Z: start of simulated campaigns

IK_SEEDS = np.array([[0, 0, 0, 0, 0, 0], [0, 0.5, 0, 0, 0.8, 0], [0.5, 0.3, -0.3, 0, 1, 0],
                     [-0.5, 0.3, -0.3, 0, 1, 0], [0, 0.6, -0.6, 1.5, 1, 0], [0, 0.6, -0.6, -1.5, 1, 0],
                     [0.3, 0.8, 0, 3, 0.5, 0], [-0.3, 0.8, 0, -3, -0.5, 0]], float)


@dataclass(frozen=True)
class Noise:
    """Error sources of a campaign; `scale` multiplies all (0 turns every one off)."""

    repeatability_3sigma_m: float = 1e-4
    encoder_counts_per_rev: int = 2**17
    jig_error_m: float = 2e-5  # per-face machining error, uniform within ±this
    scale: float = 1.0


@dataclass(frozen=True)
class Campaign:
    """How the campaign is run (what the integrator programs)."""

    contacts: int = 100
    seed: int = 0
    rate_hz: float = 250.0
    approach_offset_m: float = 0.040  # nominal stand-off; must exceed the model error
    search_speed_m_s: float = 0.010
    search_travel_m: float = 0.090
    max_tilt_rad: float = np.radians(30)
    joint_speed_rad_s: float = 1.0
    dwell_s: float = 0.2
    start_ns: int = EPOCH_NS


@dataclass
class SimResult:
    """A simulated campaign: what the controller logged, and the truth kept apart."""

    stream_t_ns: np.ndarray  # (T,) int64
    stream_q: np.ndarray  # (T, n_joints) rad, quantised
    contact_t_ns: np.ndarray  # (n,)
    contact_q: np.ndarray  # (n, n_joints) latched, quantised
    contact_face: list[str]
    contact_axis: np.ndarray  # (n,) 0/1/2
    contact_coordinate: np.ndarray  # (n,) m, drawing value
    injected_along_normal_m: np.ndarray  # (n,) true tip minus drawing, along the face axis
    face_errors_m: dict[str, float] = field(default_factory=dict)
    dropped_targets: int = 0

    @property
    def injected_noise_rms_m(self) -> float:
        return float(np.sqrt(np.mean(self.injected_along_normal_m**2)))


def _targets(jig: Jig, n: int, rng: np.random.Generator, offset: float, max_tilt: float):
    """n candidate targets spread evenly over the faces: face index, approach point, tool rotation."""
    faces = np.arange(n) % len(jig.faces)
    rng.shuffle(faces)
    P = np.zeros((n, 3))
    R = np.zeros((n, 3, 3))
    for fi, f in enumerate(jig.faces):
        idx = np.flatnonzero(faces == fi)
        a, b = f.other_axes()
        P[idx, f.axis_index] = f.coordinate + offset * f.normal_sign
        P[idx, a] = rng.uniform(*f.extent[0], idx.size)
        P[idx, b] = rng.uniform(*f.extent[1], idx.size)
        z = -f.normal  # wire direction: into the face
        t = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
        xa = np.cross(t, z)
        xa /= np.linalg.norm(xa)
        B = np.stack([xa, np.cross(z, xa), z], axis=1)
        az, spin = rng.uniform(-np.pi, np.pi, (2, idx.size))
        tilt = max_tilt * np.sqrt(rng.uniform(0, 1, idx.size))
        R[idx] = B @ rot("z", az) @ rot("x", tilt) @ rot("z", spin)
    return faces, P, R


def _quantise(q: np.ndarray, counts: int, on: bool) -> np.ndarray:
    if not on:
        return q
    step = 2 * np.pi / counts
    return np.round(q / step) * step


def simulate(nominal: SerialArm, truth: SerialArm, jig: Jig, campaign: Campaign = Campaign(),
             noise: Noise = Noise()) -> SimResult:
    """Run a campaign (see module docstring).  Deterministic for a given `campaign.seed`."""
    rng = np.random.default_rng(campaign.seed)
    xn, xt = nominal.vector(), truth.vector()
    k = noise.scale
    face_err = {f.id: float(k * rng.uniform(-noise.jig_error_m, noise.jig_error_m)) for f in jig.faces}
    sig_rep = k * noise.repeatability_3sigma_m / 3

    want = campaign.contacts
    kept: list[dict] = []
    dropped = 0
    for _round in range(20):
        need = want - sum(len(b["s"]) for b in kept)
        if need <= 0:
            break
        n_try = int(need * 2.2) + 8
        faces, P, R = _targets(jig, n_try, rng, campaign.approach_offset_m, campaign.max_tilt_rad)
        q_a, ok = ik.solve(xn, P, R, IK_SEEDS, nominal.lower, nominal.upper, iters=40)
        faces, P, R, q_a = faces[ok], P[ok], R[ok], q_a[ok]
        # search direction in joint space: nominal tip along −normal, orientation fixed
        normals = np.stack([jig.faces[f].normal for f in faces]) if faces.size else np.zeros((0, 3))
        Jp = ik.pose_jacobian(xn, q_a)
        twist = np.concatenate([-normals, np.zeros_like(normals)], axis=1)
        dq = np.linalg.solve(Jp, twist[..., None])[..., 0]  # rad per m of search travel
        eps = rng.normal(0, sig_rep, (faces.size, 3))  # repeatability: actual tip vs encoder-predicted
        axis = np.array([jig.faces[f].axis_index for f in faces], int)
        sign = np.array([jig.faces[f].normal_sign for f in faces], float)
        c_true = np.array([jig.faces[f].coordinate + face_err[jig.faces[f].id] for f in faces])
        rows = np.arange(faces.size)

        def gap(s: np.ndarray) -> np.ndarray:
            p = serial_arm.tip_position(xt, q_a + s[:, None] * dq) + eps
            return sign * (p[rows, axis] - c_true)

        s = np.zeros(faces.size)
        g0 = gap(s)
        for _ in range(8):  # Newton on the search travel (g is nearly linear in s)
            h = 1e-6
            slope = (gap(s + h) - gap(s - h)) / (2 * h)
            s = s - gap(s) / slope
        p_true = serial_arm.tip_position(xt, q_a + s[:, None] * dq)
        on_face = np.ones(faces.size, bool)
        for i, f in enumerate(faces):
            fc = jig.faces[f]
            a, b = fc.other_axes()
            on_face[i] = (fc.extent[0][0] <= p_true[i, a] <= fc.extent[0][1]
                          and fc.extent[1][0] <= p_true[i, b] <= fc.extent[1][1])
        q_c = q_a + s[:, None] * dq  # where the search latches: a controller stops a search at a joint limit
        within = np.all((q_c >= nominal.lower) & (q_c <= nominal.upper), axis=1)
        good = (g0 > 0) & (s > 0) & (s < campaign.search_travel_m) & on_face & (np.abs(gap(s)) < 1e-10) & within
        dropped += int((~good).sum())
        idx = np.flatnonzero(good)[:need]
        kept.append({"face": faces[idx], "q_a": q_a[idx], "dq": dq[idx], "s": s[idx], "axis": axis[idx]})
    if sum(len(b["s"]) for b in kept) < want:
        raise RuntimeError(f"could only place {sum(len(b['s']) for b in kept)} of {want} contacts on the jig")

    face = np.concatenate([b["face"] for b in kept])
    q_a = np.concatenate([b["q_a"] for b in kept])
    dq = np.concatenate([b["dq"] for b in kept])
    s = np.concatenate([b["s"] for b in kept])
    axis = np.concatenate([b["axis"] for b in kept])
    quant = k > 0
    q_latch = _quantise(q_a + s[:, None] * dq, noise.encoder_counts_per_rev, quant)
    coord = np.array([jig.faces[f].coordinate for f in face])
    p_rec = serial_arm.tip_position(xt, q_latch)
    injected = p_rec[np.arange(face.size), axis] - coord

    t_ns, q_stream, t_contact = _timeline(q_a, dq, s, campaign, nominal.n_joints)
    q_stream = _quantise(q_stream, noise.encoder_counts_per_rev, quant)
    return SimResult(stream_t_ns=t_ns, stream_q=q_stream, contact_t_ns=t_contact, contact_q=q_latch,
                     contact_face=[jig.faces[f].id for f in face], contact_axis=axis, contact_coordinate=coord,
                     injected_along_normal_m=injected, face_errors_m=face_err, dropped_targets=dropped)


def _timeline(q_a: np.ndarray, dq: np.ndarray, s: np.ndarray, c: Campaign, nj: int):
    """Joint trajectory of the campaign sampled at the controller rate, and contact times.

    Segments per contact: move to approach (cosine profile), dwell, search (constant speed),
    dwell (latched), retract (cosine profile).  Vectorised: a sample's segment is found with
    `searchsorted` and interpolated in one expression.
    """
    n = s.size
    home = np.zeros(nj)
    home[1], home[4] = 0.3, 0.8
    q_contact = q_a + s[:, None] * dq
    starts, ends, kinds = [], [], []  # kind 0: cosine blend, 1: linear
    prev = home
    for i in range(n):
        starts += [prev, q_a[i], q_a[i], q_contact[i], q_contact[i]]
        ends += [q_a[i], q_a[i], q_contact[i], q_contact[i], q_a[i]]
        kinds += [0, 1, 1, 1, 0]
        prev = q_a[i]
    starts, ends, kinds = np.array(starts), np.array(ends), np.array(kinds)
    move = np.max(np.abs(ends - starts), axis=1) / c.joint_speed_rad_s * 1.5 + 0.3
    dur = move.copy()
    dur[1::5] = c.dwell_s
    dur[2::5] = s / c.search_speed_m_s
    dur[3::5] = c.dwell_s
    t_edges = np.concatenate([[0.0], np.cumsum(dur)])
    t_contact = c.start_ns + np.round(t_edges[3::5][:n] * 1e9).astype(np.int64)
    T = np.arange(0.0, t_edges[-1], 1.0 / c.rate_hz)
    seg = np.clip(np.searchsorted(t_edges, T, side="right") - 1, 0, len(dur) - 1)
    u = np.clip((T - t_edges[seg]) / dur[seg], 0, 1)
    w = np.where(kinds[seg] == 0, 0.5 - 0.5 * np.cos(np.pi * u), u)
    q = starts[seg] + w[:, None] * (ends[seg] - starts[seg])
    t_ns = c.start_ns + np.round(T * 1e9).astype(np.int64)
    return t_ns, q, t_contact


def truth_document(truth: SerialArm, noise: Noise, campaign: Campaign, sim: SimResult) -> dict:
    """TRUTH.json: the true model and the realised errors (never written to the recording)."""
    return {
        "model": truth.to_dict(),
        "noise": asdict(noise),
        "campaign": {k: v for k, v in asdict(campaign).items()},
        "injected_noise_rms_m": sim.injected_noise_rms_m,
        "face_errors_m": sim.face_errors_m,
        "dropped_targets": sim.dropped_targets,
    }
