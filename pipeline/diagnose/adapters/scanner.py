"""Effect library of the SCORBOT laser-stripe scanner (seed 001), and its adapter.

Residual (3 per corner crossing, m, base frame {B}): r = P(x; pixel, q) − corner
(`pipeline.systems.scorbot_scanner.ScannerModel`).  Each effect's signature S (n, 3, k) is the
change of the model's prediction P per unit parameter at the geometric solution x — the
analytic chain rule through the reconstruction (sign conventions shared with
`pipeline.simulate.scorbot_scanner`, which injects the same physics into the TRUE camera/arm):

- ``radial_k2@camera`` (1/m⁴) and ``tangential_distortion@camera`` (p1, p2 in 1/m; both in the
  fitted gauge — f held at its nominal — so k2·f⁴ and p·f are the gauge-free values): the true
  lens maps distorted sensor coordinates (ũ, ṽ) (m) to ideal ones as the model's
  u = ũ(1 + k r̃²) plus Δ(ũ, ṽ)::

      Δu = k2 r̃⁴ ũ + 2 p1 ũṽ + p2 (r̃² + 2ũ²),   Δv = k2 r̃⁴ ṽ + p1 (r̃² + 2ṽ²) + 2 p2 ũṽ

  → S = ∂P/∂(u, v) · ∂Δ/∂θ;
- ``stripe_peak_bias@camera`` (px): the detected stripe centre lies b pixels across the stripe
  (along its image normal n̂, +V side) from the true peak → S = −∂P/∂(U, V) · n̂, with
  ∂P/∂(U, V) = ∂P/∂(u, v) · ∂(u, v)/∂(ũ, ṽ) · diag(s_u, s_v).  Across a near-horizontal stripe
  this is a shift of v0, so only stripes crossing the image at varied slopes could expose it;
- ``time_offset@camera`` (s): the image is captured at t + δ, the encoders latched at t: the
  camera stands at q + q̇·δ (q̇ from the encoder stream) → S = ∂P/∂q · q̇;
- ``joint_offset@J<i>`` (rad, when the geometric model has no joint offsets) and
  ``joint_scale@J<i>`` (1): true angle q_i + δ (+ ε·q_i) → S = ∂P/∂q_i (· q_i).

∂P/∂q_i = z_i × (P − o_i) (joint i's axis z_i through o_i in {B}).  The joint refit does not add the lens
effects as S·θ: `refit_terms` reconstructs the points through the lens with them (the reconstruction is
not linear in (u, v); the additive term biased p2 by ≈ 1 % at 4× its MDS on spread campaigns).  `adapter(model, table)`
returns the `diagnose.Adapter` (library, signatures, lack-of-fit variables: each joint angle
through ∂P/∂q_i, time per axis of {B}, image column U through ∂P/∂(U, V)).
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.adapters.scanner_noise import (  # noqa: F401  (re-exported)
    _skew,
    encoder_basis,
    joint_motion,
    pose_basis,
    repeatability_basis,
    repeatability_model,
    stripe_directions,
)
from pipeline.diagnose.library.lens import (
    lens_excess,
    lens_excess_jacobian,
    stripe_normals,
)
from pipeline.diagnose.library.term import Effect
from pipeline.diagnose.verdict import lack_of_fit
from pipeline.models import camera as cam
from pipeline.models import serial_arm

PLAUSIBLE = {
    "radial_k2": 2e8,  # 1/m⁴ (normalised k2·f⁴ ≈ 0.55 for f = 7.25 mm)
    "tangential_distortion": 2.0,  # 1/m (normalised p·f ≈ 0.015: a strongly decentred lens)
    "stripe_peak_bias": 0.5,  # px
    "time_offset": 0.1,  # s (a few video frames)
    "joint_offset": 2e-2,  # rad (1.1°)
    "joint_scale": 5e-3,
}

ADVICE = {
    "radial_k2": "place the stripe crossings over the whole image, out to its corners: stripe rows over the whole "
                 "image height and crossings spread along the stripe to the image edges, not the central ones, more "
                 "per pose (robocal simulate scorbot-scanner --spread --corners 8 --poses 20)",
    "tangential_distortion": "place the stripe crossings over the whole image (more poses and corners, "
                             "e.g. --poses 20 --corners 6) so that both image axes are covered",
    "stripe_peak_bias": "a constant offset across a near-horizontal stripe is a shift of the principal point v0: "
                        "measure the peak detector's bias on a target of known profile, or scan surfaces that put "
                        "the stripe at strongly varied slopes in the image",
    "time_offset": "move the arm while the image is captured (robocal simulate scorbot-scanner --capture-speed 0.1), "
                   "in varied directions, so that a late image shows as a pose error",
    "joint_offset": "spread the poses over a wider range of the joint (more poses, e.g. --poses 20)",
    "joint_scale": "spread the poses over a wider range of the joint's travel (more poses, e.g. --poses 20)",
}

# identify holds these weak gauges at the nominal on a clean campaign (docs/reference/systems/scanner.md) but frees
# them when that lowers the cost by > 10 %, which a lens effect does: the diagnosis's baseline holds them
WEAK_GAUGES = ("scanner.v0", "scanner.theta")
MIN_CAPTURE_SPEED = 1e-3  # rad/s: below this the arm is still at capture and δ has no effect


def context(model, x: np.ndarray, data, lens: tuple[float, float, float] | None = None) -> dict:
    """What the signatures are made of, at geometric parameters x: reconstructed points P,
    ∂P/∂(u, v) (n,3,2), ∂(u, v)/∂(U, V) (n,2,2), sensor coordinates, ∂P/∂q (n,3,n_joints).
    With `lens` (k2 1/m⁴, p1, p2 1/m) the camera's lens has those terms too (`lens_excess`):
    everything is evaluated through the exact reconstruction with them, and ``dP_dx`` (n,3,P)
    is the geometric Jacobian of that reconstruction."""
    x = np.asarray(x, float)
    s = x[:cam.N_SCANNER]
    px = np.asarray(data["pixel"], float)
    q = np.asarray(data["joint_positions"], float)
    ut, vt = cam.sensor_coords(px, s)
    k = s[cam.I_K]
    g = 1 + k * (ut**2 + vt**2)
    u, v = ut * g, vt * g
    dD = np.zeros((ut.size, 2, 2))
    if lens is not None:
        du, dv = lens_excess(ut, vt, *lens)
        u, v = u + du, v + dv
        dD = lens_excess_jacobian(ut, vt, *lens)
    f, th, b = s[cam.I_F], s[cam.I_TH], s[cam.I_B]
    den = v + f * np.tan(th)
    rho = b / den
    n = px.shape[0]
    dpc = np.zeros((n, 3, 2))  # p_c = ρ [v, u, f]
    dpc[:, 1, 0] = rho
    dpc[:, 0, 1] = rho
    dpc[:, :, 1] -= (rho / den)[:, None] * np.stack([v, u, np.full(n, f)], axis=1)
    R_he = cam.hand_eye_rotation(s[cam.I_W], s[cam.I_PHI], s[cam.I_PSI])
    xa = model._arm_vector(x)
    R_f, _ = serial_arm.forward(xa, q)
    dP_duv = np.einsum("nij,jk,nkl->nil", R_f, R_he, dpc)
    duv_dt = np.empty((n, 2, 2))
    duv_dt[:, 0, 0] = g + 2 * k * ut**2
    duv_dt[:, 0, 1] = duv_dt[:, 1, 0] = 2 * k * ut * vt
    duv_dt[:, 1, 1] = g + 2 * k * vt**2
    duv_dt += dD
    duv_dpx = duv_dt * np.array([s[cam.I_SU], s[cam.I_SV]])[None, None, :]
    dP_dx = None
    if lens is None:
        P = model.residuals(x, data) + np.asarray(data["corner"], float)
    else:
        P, dP_dx = model.points(x, data, (du, dv, dD))
    F = serial_arm.frames(xa, q)
    nj = q.shape[1]
    dP_dq = joint_motion(F, P, nj)
    return {"ut": ut, "vt": vt, "P": P, "dP_dx": dP_dx, "dP_duv": dP_duv,
            "dP_dpx": np.einsum("nij,njk->nik", dP_duv, duv_dpx),
            "dP_dq": dP_dq, "q": q, "qdot": np.asarray(data.get("joint_velocity", np.zeros_like(q)), float),
            "normal": stripe_normals(px, np.asarray(data.get("pose", np.zeros(n)), int))}


# ----- bases ------------------------------------------------------------------------------
def _k2(c):
    r4 = (c["ut"]**2 + c["vt"]**2) ** 2
    return np.einsum("nij,nj->ni", c["dP_duv"], np.stack([r4 * c["ut"], r4 * c["vt"]], 1))[:, :, None]


def _tangential(c):
    ut, vt = c["ut"], c["vt"]
    r2 = ut**2 + vt**2
    d1 = np.stack([2 * ut * vt, r2 + 2 * vt**2], 1)  # ∂Δ/∂p1
    d2 = np.stack([r2 + 2 * ut**2, 2 * ut * vt], 1)  # ∂Δ/∂p2
    return np.stack([np.einsum("nij,nj->ni", c["dP_duv"], d) for d in (d1, d2)], axis=2)


def _bias(c):
    return -np.einsum("nij,nj->ni", c["dP_dpx"], c["normal"])[:, :, None]


def _time(c):
    return np.einsum("nij,nj->ni", c["dP_dq"], c["qdot"])[:, :, None]


def _joint_offset(i):
    return lambda c: c["dP_dq"][:, :, i:i + 1]


def _joint_scale(i):
    return lambda c: c["dP_dq"][:, :, i:i + 1] * c["q"][:, i][:, None, None]


# ----- the library ------------------------------------------------------------------------
def library(model, table) -> list[Effect]:
    """Every candidate effect of a scanner campaign (module docstring).  Joint offsets are
    candidates only when the geometric model does not identify them already."""
    P = PLAUSIBLE
    q = np.asarray(table["joint_positions"], float)
    px = np.asarray(table["pixel"], float)
    qd = np.asarray(table.get("joint_velocity", np.zeros_like(q)), float)
    speed = float(np.max(np.abs(qd))) if qd.size else 0.0
    lib: list[Effect] = [
        Effect("radial_k2", "camera", ("k2",), ("1/m^4",), P["radial_k2"], "direct", _k2, 10, "pixel_U",
               ADVICE["radial_k2"], data={"located": ("image column U (px)", px[:, 0])}),
        Effect("tangential_distortion", "camera", ("p1", "p2"), ("1/m", "1/m"), P["tangential_distortion"], "direct",
               _tangential, 15, "pixel_U", ADVICE["tangential_distortion"],
               data={"located": ("image column U (px)", px[:, 0])}),
        Effect("stripe_peak_bias", "camera", ("peak_bias",), ("px",), P["stripe_peak_bias"], "direct", _bias, 20,
               "pixel_U", ADVICE["stripe_peak_bias"], data={"located": ("image row V (px)", px[:, 1])}),
    ]
    blocked = {} if speed >= MIN_CAPTURE_SPEED else {
        "blocked": f"the arm stands still at every capture (largest joint speed {speed:.2g} rad/s): a camera-to-"
                   f"encoder time offset has no effect on these images", "absorbed_by": "nothing (no motion)"}
    lib.append(Effect("time_offset", "camera", ("time_offset",), ("s",), P["time_offset"], "direct", _time, 30,
                      "time", ADVICE["time_offset"],
                      data={"located": ("joint speed at capture (rad/s)", np.linalg.norm(qd, axis=1)), **blocked}))
    names = [j.name for j in model.arm.joints]
    if not model.joint_offsets:
        for i, j in enumerate(names):
            lib.append(Effect("joint_offset", j, (f"offset_{j}",), ("rad",), P["joint_offset"], "direct",
                              _joint_offset(i), 40, f"q_{j}", ADVICE["joint_offset"],
                              data={"located": (f"{j} (rad)", q[:, i])}))
    for i, j in enumerate(names):
        lib.append(Effect("joint_scale", j, (f"scale_{j}",), ("1",), P["joint_scale"], "direct", _joint_scale(i), 50,
                          f"q_{j}", ADVICE["joint_scale"], data={"located": (f"{j} (rad)", q[:, i])}))
    return lib


def signatures(model, x: np.ndarray, data, effects) -> list[np.ndarray]:
    """Signature (n, 3, k_e) m/unit of each effect at geometric parameters x."""
    if not effects:
        return []
    c = context(model, x, data)
    return [np.asarray(e.basis(c), float) for e in effects]


LENS = {"radial_k2": (0,), "tangential_distortion": (1, 2)}  # effect → its slots in (k2, p1, p2)


def refit_terms(model, x: np.ndarray, theta: np.ndarray, data, effects, jac: bool = False):
    """Residual (n,3) m of the geometry x plus `effects` with parameters `theta` (their own
    units, concatenated), and with `jac` the Jacobian (n,3,P + Σk) per unit of (x, theta).

    The lens effects (k2, p1, p2) enter exactly: the points are reconstructed through the lens
    with those terms (u = ũ(1 + k r̃²) + Δ(ũ, ṽ)), as the simulator's camera images them, not as
    S·θ — the reconstruction is not linear in (u, v), and the additive term leaves a bias
    of ≈ 1 % of p2 at 4× its MDS on the spread campaign (docs/guide/diagnose.md).  The other effects
    stay additive, their signatures evaluated through that lens."""
    theta = np.asarray(theta, float)
    lens = np.zeros(3)
    i = 0
    for e in effects:
        if e.name in LENS:
            lens[list(LENS[e.name])] += theta[i:i + e.k]
        i += e.k
    has_lens = any(e.name in LENS for e in effects)
    c = context(model, x, data, tuple(lens) if has_lens else None)
    S = [np.asarray(e.basis(c), float) for e in effects]
    r = c["P"] - np.asarray(data["corner"], float)
    i = 0
    for e, Se in zip(effects, S):
        if e.name not in LENS:
            r = r + np.einsum("nkc,c->nk", Se, theta[i:i + e.k])
        i += e.k
    if not jac:
        return r
    Jx = c["dP_dx"] if c["dP_dx"] is not None else model.jacobian(x, data)
    return r, np.concatenate([Jx] + S, axis=2)


def exact_refit(model, effects):
    """The joint refit's model of `effects` (`augmented.AugmentedModel.exact`): `refit_terms` when a
    lens effect is among them, else None (the additive model is exact to first order there)."""
    if not any(e.name in LENS for e in effects):
        return None
    return lambda x, th, data, eff, jac=False: refit_terms(model, x, th, data, eff, jac)


def variables(model, x: np.ndarray, table) -> list[lack_of_fit.Variable]:
    """Lack-of-fit variables (rows = flattened residual rows, n·3): each joint angle through
    ∂P/∂q_i, the image column U through ∂P/∂(U, V) (a pixel error varying along the stripe),
    and time since start (per axis of {B})."""
    c = context(model, x, table)
    q = c["q"]
    n = q.shape[0]
    out = []
    for i, j in enumerate(model.arm.joints):
        v = lack_of_fit.smooth_variable(f"q_{j.name}", "rad", np.repeat(q[:, i], 3), c["dP_dq"][:, :, i].reshape(-1, 1),
                                        K=6)
        if v is not None:
            out.append(v)
    px = np.asarray(table["pixel"], float)
    v = lack_of_fit.smooth_variable("pixel_U", "px", np.repeat(px[:, 0], 3), c["dP_dpx"].reshape(n * 3, 2), K=5)
    if v is not None:
        out.append(v)
    if "time_since_start_s" in table:
        t = np.asarray(table["time_since_start_s"], float)
        v = lack_of_fit.smooth_variable("time_since_start_s", "s", np.repeat(t, 3), np.tile(np.eye(3), (n, 1)), K=4)
        if v is not None:
            out.append(v)
    return out


def adapter(model, table, lib: list[Effect] | None = None):
    """`diagnose.Adapter` of a scanner diagnosis table (`add_context`)."""
    from pipeline.diagnose.adapters.adapter import Adapter

    lib = library(model, table) if lib is None else lib
    return Adapter(library=lib,
                   signatures=lambda x, data, effects: signatures(model, x, data, effects),
                   variables=lambda x: variables(model, x, table),
                   time_s=np.asarray(table["time_since_start_s"], float),
                   located=lambda e: e.data.get("located"),
                   cluster=np.asarray(table["pose"]) if "pose" in table else None,
                   cluster_basis=(lambda x: pose_basis(model, x, table)) if "pose" in table else None,
                   noise_shape=lambda x: [context(model, x, table)["dP_dpx"], stripe_directions(table)],
                   cluster_model=(lambda x: repeatability_model(model, x, table)) if "pose" in table else None,
                   held=WEAK_GAUGES,
                   refit=lambda effects: exact_refit(model, effects))


def add_context(table: dict, stream_t: np.ndarray, stream_q: np.ndarray) -> dict:
    """A copy of a stripe table with ``joint_velocity`` (n, n_joints) rad/s — the encoder
    stream's central difference (one sample each side) at each capture — and
    ``time_since_start_s`` (n,)."""
    t_ns = np.asarray(table["timestamp_ns"], np.int64)
    st = np.asarray(stream_t, np.int64)
    ts = (st - st[0]) * 1e-9
    tq = (t_ns - st[0]) * 1e-9
    h = float(np.median(np.diff(ts))) if ts.size > 1 else 0.01
    sq = np.asarray(stream_q, float)
    qd = np.stack([(np.interp(tq + h, ts, sq[:, j]) - np.interp(tq - h, ts, sq[:, j])) / (2 * h)
                   for j in range(sq.shape[1])], axis=1)
    out = dict(table)
    out["joint_velocity"] = qd
    out["time_since_start_s"] = tq
    return out


def from_recording(rec, stream=None):
    """(ScannerModel, diagnosis table, info) of a scorbot-scanner recording; `stream` (a
    `JointStream` already decoded, e.g. by the ingest stage) saves decoding it again."""
    from pipeline.ingest.streams import joint_stream
    from pipeline.systems import scorbot_scanner as sc

    model, table = sc.load(rec)
    stream = joint_stream(rec) if stream is None else stream
    return model, add_context(table, stream.t_ns, stream.q), {"system": sc.SYSTEM}


def effect_by_name(model, table, name: str, location: str | None) -> Effect:
    """The library entry `name@location` (location may be omitted when unique)."""
    from pipeline.diagnose.library.term import pick

    return pick(library(model, table), name, location)
