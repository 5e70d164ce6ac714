"""Seed 001: laser-stripe scanner (camera + stripe projector) on a 5-axis SCORBOT-ER VII.

Measurement (eq. 17): a stripe pixel known to lie on a target corner P (m, base frame {B})
gives three residuals ``r = ρ·T·U − P`` (m): the stripe point reconstructed by eq. 13 minus
the corner.  Parameters: the 14 of eq. 14 (`pipeline.models.camera`), optionally followed
by the five joint offsets of the arm (joint identification, the paper's proposed extension).

Gauge freedom (exact, for any data): scaling (f, s_u, s_v) by λ and k by 1/λ² leaves every
reconstructed point unchanged — ρ·[v, u, f] is homogeneous of degree 0 in that scaling.
Only s_u/f, s_v/f and k·f² are identifiable; f is held at its nominal value (priority:
last), and the rank test names the dependency.  With joint offsets, J5's offset rotates the
camera about the flange axis exactly as (w, tx, ty) do, so it is not identifiable either.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.identify.model import Table
from pipeline.measurements.sensed_point import SensedPointModel
from pipeline.models import camera as cam
from pipeline.models.transforms import rot as _rot
from pipeline.models.serial_arm import Joint, SerialArm
from pipeline.models.stripe_sensor import StripeSensor

SYSTEM = "scorbot-scanner"
MEASUREMENT_CHANNEL = "/scanner/stripe"
META_SCANNER = "robocal.scanner"  # metadata record: image size and parameter bounds
MM, DEG = 1e-3, np.pi / 180
IMAGE_SIZE_PX = (640, 480)  # Sony XC-55: 640 x 480 progressive-scan CCD

# Table 2 of seed 001, converted to SI: (lower, upper, estimated value)
TABLE2 = {
    "f": (6 * MM, 10 * MM, 7.25 * MM),
    "s_u": (0.005 * MM, 0.1 * MM, 0.0066 * MM),
    "s_v": (0.005 * MM, 0.1 * MM, 0.0074 * MM),
    "u0": (290.0, 340.0, 315.2),
    "v0": (200.0, 250.0, 232.8),
    "k": (0.0, 0.1 / MM**2, 0.00062 / MM**2),
    "b": (100 * MM, 200 * MM, 139.9 * MM),
    "theta": (0.0, 45 * DEG, 26.5 * DEG),
    "w": (-5 * DEG, 5 * DEG, 1.28 * DEG),
    "phi": (-5 * DEG, 5 * DEG, 2.02 * DEG),
    "psi": (-5 * DEG, 5 * DEG, 0.91 * DEG),
    "tx": (50 * MM, 100 * MM, 68.4 * MM),
    "ty": (-10 * MM, 0.0, -4.52 * MM),
    "tz": (-100 * MM, -50 * MM, -63.5 * MM),
}


def bounds() -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds (SI) of the 14 scanner parameters, Table 2."""
    lo = np.array([TABLE2[n][0] for n in cam.SCANNER_NAMES])
    hi = np.array([TABLE2[n][1] for n in cam.SCANNER_NAMES])
    return lo, hi


def reference_scanner() -> np.ndarray:
    """Default simulator truth: Table 2's estimated values (SI)."""
    return np.array([TABLE2[n][2] for n in cam.SCANNER_NAMES])


def nominal_scanner() -> np.ndarray:
    """What is known before calibration: the middle of each bound."""
    lo, hi = bounds()
    return 0.5 * (lo + hi)


# SCORBOT-ER VII D-H (seed 001 Table 1; dimensions from the Eshed Robotec user manual, see
# docs/reference/systems/scanner.md): (alpha deg, a mm, d mm, lower deg, upper deg)
_DH = [(-90, 50.0, 358.5, -155, 155), (0, 300.0, 0.0, -135, 35), (0, 350.0, 0.0, -130, 130),
       (-90, 0.0, 0.0, -130, 130), (0, 0.0, 251.0, -180, 180)]


def nominal_arm() -> SerialArm:
    """Nominal SCORBOT-ER VII: base frame {B} on the mounting surface, flange {E} at the roll axis."""
    zero6 = {k: 0.0 for k in ("x", "y", "z", "rz", "rx", "ry")}
    joints = tuple(Joint(name=f"J{i + 1}", alpha=al * DEG, a=a * MM, d=d * MM, lower=lo * DEG, upper=hi * DEG)
                   for i, (al, a, d, lo, hi) in enumerate(_DH))
    return SerialArm(name="SCORBOT-ER VII nominal", base=dict(zero6), joints=joints,
                     tool={k: 0.0 for k in ("x", "y", "z", "rz", "ry", "rx")})


def random_scanner(rng: np.random.Generator) -> np.ndarray:
    """A scanner truth drawn uniformly within the Table 2 bounds."""
    lo, hi = bounds()
    return rng.uniform(lo, hi)


def gauge_invariants(s: np.ndarray) -> dict[str, float]:
    """Identifiable combinations of the scanner parameters (SI): everything but f, with
    s_u, s_v and k expressed relative to f (see module docstring)."""
    s = np.asarray(s, float)
    out = {"s_u/f": s[cam.I_SU] / s[cam.I_F], "s_v/f": s[cam.I_SV] / s[cam.I_F], "k*f^2": s[cam.I_K] * s[cam.I_F] ** 2}
    R = cam.hand_eye_rotation(s[cam.I_W], s[cam.I_PHI], s[cam.I_PSI])
    out.update({n: float(s[i]) for n, i in (("u0", cam.I_U0), ("v0", cam.I_V0), ("b", cam.I_B), ("theta", cam.I_TH),
                                            ("tx", cam.I_TX), ("ty", cam.I_TY), ("tz", cam.I_TZ))})
    for i in range(3):
        for j in range(3):
            out[f"R_he[{i},{j}]"] = float(R[i, j])
    return {k: float(v) for k, v in out.items()}


@dataclass(frozen=True)
class ScannerModel(SensedPointModel):
    """Seed 001 as a composition: the SCORBOT arm (`SerialArm`) + the laser-stripe scanner
    (`StripeSensor`) + a point known to be a target's corner (`SensedPointModel`).

    Data columns: ``joint_positions`` (n,5) rad, ``pixel`` (n,2) px (U, V), ``corner`` (n,3) m
    in {B}; optional ``pose`` (n,) observation index.  `nominal_x` is the nominal scanner
    vector (14,); with `joint_offsets` the arm's 5 joint offsets follow it.
    """

    arm: SerialArm = field(default_factory=nominal_arm)
    sensor: StripeSensor = field(default_factory=StripeSensor)
    nominal_x: tuple[float, ...] = tuple(nominal_scanner())
    joint_offsets: bool = False
    image_size: tuple[int, int] = IMAGE_SIZE_PX
    lower: tuple[float, ...] = tuple(bounds()[0])
    upper: tuple[float, ...] = tuple(bounds()[1])
    search_samples: int = 1024

    system = SYSTEM

    def priority(self) -> np.ndarray:
        """Scanner parameters first, joint offsets next, then v0 and θ (gauge directions that
        only lens distortion breaks), f last (the exact scale gauge)."""
        p = np.zeros(len(self.parameter_names()), int)
        p[cam.N_SCANNER:] = 1
        p[[cam.I_V0, cam.I_TH]] = 2
        p[cam.I_F] = 3
        return p

    def batch_cost(self, X: np.ndarray, data: Table) -> np.ndarray:
        """Eq. 18's J (m²) for many scanner vectors X (C,14) at once (arm at its nominal)."""
        return self.batch_cost_fn(data)(X)

    def batch_cost_fn(self, data: Table):
        """`batch_cost` with the flange-frame corners computed once (for the GA's loop)."""
        px = np.asarray(data["pixel"], float)
        R_f, t_f = self.flange(self.nominal(), data["joint_positions"])
        p_f = np.einsum("nji,nj->ni", R_f, np.asarray(data["corner"], float) - t_f)  # corners, flange frame
        return lambda X: _batch_cost(np.atleast_2d(np.asarray(X, float)), px, p_f)

    def extra_metrics(self, x_start: np.ndarray, x: np.ndarray, data: Table) -> dict:
        """Scanner figures for results.json: error at the nominal (bound midpoints), gauge-free values."""
        r_nom = self.residuals(self.nominal(), data)
        e = np.linalg.norm(self.residuals(x, data), axis=1)
        return {"scanner": {
            "rms_at_nominal_m": float(np.sqrt(np.mean(r_nom**2))),
            "mean_3d_error_m": float(e.mean()), "max_3d_error_m": float(e.max()),
            "gauge": {"exact": "(f, s_u, s_v, k) -> (λf, λs_u, λs_v, k/λ²): f held at its nominal",
                      "weak": "v0 and theta: exact gauge directions for a distortion-free lens; held at their "
                              "nominal unless the rank test finds them supported"},
            "invariants": gauge_invariants(x[:cam.N_SCANNER])}}

    # ----- global start -------------------------------------------------------------------
    def initial_guess(self, data: Table, seed: int = 0) -> np.ndarray:
        """Global search inside the Table 2 bounds (no other prior), see `global_start`."""
        return global_start(self, data, seed=seed)[0]

    def describe(self, x: np.ndarray) -> dict:
        """Model JSON: arm (with joint offsets), camera, laser, hand-eye — SI units."""
        x = np.asarray(x, float)
        s = x[:cam.N_SCANNER]
        arm = self.arm
        if self.joint_offsets:
            arm = arm.with_vector(self._arm_vector(x))
        v = {n: float(s[i]) for i, n in enumerate(cam.SCANNER_NAMES)}
        return {
            "kind": "scorbot_scanner",
            "name": "SCORBOT-ER VII laser-stripe scanner",
            "units": {"length": "m", "angle": "rad", "pixel_pitch": "m/px", "k": "1/m^2"},
            "arm": arm.to_dict(),
            "camera": {**{n: v[n] for n in ("f", "s_u", "s_v", "u0", "v0", "k")},
                       "image_width_px": int(self.image_size[0]), "image_height_px": int(self.image_size[1]),
                       "model": "seed 001 eqs. 1-4: s=pixel pitch, u=ũ(1+k r²)"},
            "laser": {"b": v["b"], "theta": v["theta"], "plane": "x + z tan(theta) = b in the camera frame"},
            "hand_eye": {**{n: v[n] for n in ("w", "phi", "psi", "tx", "ty", "tz")},
                         "convention": "T_flange_camera: R = Rz(w) Ry(phi) Rz(psi), t = (tx, ty, tz)"},
            "gauge": {"fixed": "f", "invariants": gauge_invariants(s),
                      "note": "(f, s_u, s_v, k) -> (λf, λs_u, λs_v, k/λ²) gives identical points"},
        }


def _batch_cost(X: np.ndarray, px: np.ndarray, p_f: np.ndarray) -> np.ndarray:
    """J (m²) per row of X (C,14) for pixels px (n,2) and flange-frame corners p_f (n,3)."""
    f, su, sv, u0, v0, k, b, th = (X[:, i:i + 1] for i in range(8))
    ut, vt = su * (px[:, 0] - u0), sv * (px[:, 1] - v0)
    g = 1 + k * (ut**2 + vt**2)
    u, v = ut * g, vt * g
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = b / (v + f * np.tan(th))
    pc = rho[..., None] * np.stack([v, u, np.broadcast_to(f, u.shape)], axis=2)
    R = _rot("z", X[:, cam.I_W]) @ _rot("y", X[:, cam.I_PHI]) @ _rot("z", X[:, cam.I_PSI])
    P = np.einsum("cij,cnj->cni", R, pc) + X[:, None, cam.I_TX:cam.I_TZ + 1]
    J = np.sum((P - p_f) ** 2, axis=(1, 2))
    return np.where(np.isfinite(J), J, np.inf)


# ----- global start: variable projection over the camera/laser, Umeyama for the rest --------
def _reduced_bounds(model: ScannerModel) -> tuple[np.ndarray, np.ndarray]:
    """Box of z = (ln s_u/f, ln s_v/f, u0, v0, k f², θ) implied by the Table 2 bounds."""
    lo, hi = np.asarray(model.lower), np.asarray(model.upper)
    zl = np.array([np.log(lo[cam.I_SU] / hi[cam.I_F]), np.log(lo[cam.I_SV] / hi[cam.I_F]), lo[cam.I_U0],
                   lo[cam.I_V0], lo[cam.I_K] * lo[cam.I_F] ** 2, lo[cam.I_TH]])
    zh = np.array([np.log(hi[cam.I_SU] / lo[cam.I_F]), np.log(hi[cam.I_SV] / lo[cam.I_F]), hi[cam.I_U0],
                   hi[cam.I_V0], hi[cam.I_K] * hi[cam.I_F] ** 2, hi[cam.I_TH]])
    return zl, zh


def _unit_points(Z: np.ndarray, px: np.ndarray) -> np.ndarray:
    """Camera-frame stripe points for b = 1 and f = 1 at reduced parameters Z (C,6): (C,n,3)."""
    au, av, u0, v0, kap, th = (np.exp(Z[:, 0]), np.exp(Z[:, 1]), Z[:, 2], Z[:, 3], Z[:, 4], Z[:, 5])
    ut = au[:, None] * (px[None, :, 0] - u0[:, None])
    vt = av[:, None] * (px[None, :, 1] - v0[:, None])
    g = 1 + kap[:, None] * (ut**2 + vt**2)
    u, v = ut * g, vt * g
    den = v + np.tan(th)[:, None]
    den = np.where(den > 1e-9, den, np.nan)  # point behind the laser: invalid
    return np.stack([v / den, u / den, 1 / den], axis=2)


WEAK = ("v0", "theta")  # gauge directions that only lens distortion breaks (see docs/reference/systems/scanner.md)


def global_start(model: ScannerModel, data: Table, seed: int = 0):
    """Initial scanner parameters from the bounds alone.

    For fixed (s_u/f, s_v/f, u0, v0, k f², θ) the points ρ[v,u,f] are known up to the scale
    b, and the flange-frame corners T_flange⁻¹·P must equal b·R_he·p + t_he: a similarity
    transform solved in closed form (Umeyama).  The cost of eq. 18 is the same in the
    flange frame (T_flange is rigid), so this is exact variable projection: a 4-D search
    over (s_u/f, s_v/f, u0, k f²) (Sobol samples + bounded trust-region refinement) replaces
    the 14-D one.  v0 and θ stay at their nominal values — with an undistorted lens they are
    exact gauge directions — unless a 6-D search that frees them lowers the cost by more than
    noise could (> 10 %).  Returns (x0, SearchResult).
    """
    from pipeline.identify.global_search import multistart, similarity_batch

    px = np.asarray(data["pixel"], float)
    x_nom = model.nominal()
    R_f, t_f = model.flange(x_nom, data["joint_positions"])
    p_f = np.einsum("nji,nj->ni", R_f, np.asarray(data["corner"], float) - t_f)
    zl, zh = _reduced_bounds(model)
    z_fixed = np.array([x_nom[cam.I_V0], x_nom[cam.I_TH]])
    free4 = np.array([0, 1, 2, 4])

    def batch_residuals(Z: np.ndarray) -> np.ndarray:
        if Z.shape[1] == 4:
            Z6 = np.empty((Z.shape[0], 6))
            Z6[:, free4] = Z
            Z6[:, [3, 5]] = z_fixed
            Z = Z6
        A = _unit_points(Z, px)
        ok = np.all(np.isfinite(A), axis=(1, 2))
        out = np.full((Z.shape[0], p_f.size), np.nan)
        if ok.any():
            sc, R, t, _ = similarity_batch(A[ok], p_f)
            r = sc[:, None, None] * np.einsum("cnj,cij->cni", A[ok], R) + t[:, None, :] - p_f
            r[sc <= 0] = np.nan  # b > 0: the laser is on the +x side
            out[ok] = r.reshape(r.shape[0], -1)
        return out

    def to_x(z: np.ndarray) -> np.ndarray:
        sc, R, t, _ = similarity_batch(_unit_points(z[None], px), p_f)
        f = float(x_nom[cam.I_F])
        s = np.array(x_nom[:cam.N_SCANNER], float)
        s[cam.I_SU], s[cam.I_SV] = np.exp(z[0]) * f, np.exp(z[1]) * f
        s[cam.I_U0], s[cam.I_V0] = z[2], z[3]
        s[cam.I_K] = z[4] / f**2
        s[cam.I_TH] = z[5]
        s[cam.I_B] = sc[0]  # built with b = 1 and f = 1; ρ[v,u,f] is f-free once s/f is
        s[cam.I_W], s[cam.I_PHI], s[cam.I_PSI] = cam.zyz_angles(R[0])
        s[cam.I_TX:cam.I_TZ + 1] = t[0]
        x = x_nom.copy()
        x[:cam.N_SCANNER] = s
        return x

    res = multistart(batch_residuals, zl[free4], zh[free4], n_samples=model.search_samples, seed=seed)
    z = np.empty(6)
    z[free4] = res.z
    z[[3, 5]] = z_fixed
    # v0 and θ too: taken only if they explain clearly more than noise would (10 % of the cost;
    # two extra parameters fitted to pure noise remove ~2/(3n − 13) of it)
    res6 = multistart(batch_residuals, zl, zh, n_samples=model.search_samples, seed=seed + 1)
    if res6.cost < 0.9 * res.cost:
        z, res = res6.z, res6
    x = to_x(z)
    return x, res




# ----- recordings ---------------------------------------------------------------------------
def stripe_table(rec) -> dict[str, np.ndarray]:
    """`/scanner/stripe` as one row per corner correspondence, checking every record.

    Columns: timestamp_ns, joint_positions (n,5) rad, pixel (n,2) px, corner (n,3) m,
    pose (n,) observation index, record (n,) message index.
    """
    from pipeline.errors import RobocalError, where

    msgs = rec.require(MEASUREMENT_CHANNEL)
    meta = rec.metadata.get(META_SCANNER, {})
    W, H = meta.get("image_width_px", IMAGE_SIZE_PX[0]), meta.get("image_height_px", IMAGE_SIZE_PX[1])
    cols: dict[str, list] = {k: [] for k in ("timestamp_ns", "joint_positions", "pixel", "corner", "pose", "record")}
    nj = None
    for i, m in enumerate(msgs):
        at = where(rec.path, MEASUREMENT_CHANNEL, i)
        for key in ("timestamp_ns", "joint_positions", "corner_px", "corner_m"):
            if key not in m:
                raise RobocalError(f"{at}: field {key!r} missing")
        try:
            q = np.asarray(m["joint_positions"], float)
            cpx = np.asarray(m["corner_px"], float).reshape(-1, 2) if len(m["corner_px"]) else np.zeros((0, 2))
            cm = np.asarray(m["corner_m"], float).reshape(-1, 3) if len(m["corner_m"]) else np.zeros((0, 3))
            spx = np.asarray(m.get("stripe_px", []), float).reshape(-1, 2) if m.get("stripe_px") else np.zeros((0, 2))
        except (ValueError, TypeError) as e:
            raise RobocalError(f"{at}: malformed point array ({e})") from None
        if len(m["corner_px"]) != len(m["corner_m"]):
            raise RobocalError(f"{at}: {len(m['corner_px'])} corner pixels but {len(m['corner_m'])} corner "
                               f"coordinates (counts must match)")
        nj = q.size if nj is None else nj
        if q.ndim != 1 or q.size != nj:
            raise RobocalError(f"{at}: joint_positions has {q.size} values, expected {nj}")
        for key, a in (("joint_positions", q), ("corner_px", cpx), ("corner_m", cm), ("stripe_px", spx)):
            if not np.all(np.isfinite(a)):
                raise RobocalError(f"{at}: field {key!r} has NaN or inf")
        for key, a in (("corner_px", cpx), ("stripe_px", spx)):
            bad = (a[:, 0] < 0) | (a[:, 0] > W - 1) | (a[:, 1] < 0) | (a[:, 1] > H - 1)
            if bad.any():
                j = int(np.flatnonzero(bad)[0])
                raise RobocalError(f"{at}: {key}[{j}] = ({a[j, 0]:.1f}, {a[j, 1]:.1f}) px lies outside the "
                                   f"{W}x{H} image")
        k = cpx.shape[0]
        cols["timestamp_ns"] += [int(m["timestamp_ns"])] * k
        cols["joint_positions"] += [q] * k
        cols["pixel"].append(cpx)
        cols["corner"].append(cm)
        cols["pose"] += [i] * k
        cols["record"] += [i] * k
    n = len(cols["pose"])
    if n == 0:
        raise RobocalError(f"{where(rec.path, MEASUREMENT_CHANNEL)}: no corner correspondences in any record")
    return {"timestamp_ns": np.array(cols["timestamp_ns"], np.int64),
            "joint_positions": np.array(cols["joint_positions"], float).reshape(n, nj),
            "pixel": np.concatenate(cols["pixel"]), "corner": np.concatenate(cols["corner"]),
            "pose": np.array(cols["pose"], int), "record": np.array(cols["record"], int)}


def check_pose_set(path, q_obs: np.ndarray, records: np.ndarray, min_distinct: int = 3,
                   tol_rad: float = 1e-3) -> None:
    """A `RobocalError` if the observations come from fewer than `min_distinct` distinct
    poses: one pose cannot separate the hand-eye transform from the camera (degenerate)."""
    from pipeline.errors import RobocalError, where

    reps: list[np.ndarray] = []
    for q in q_obs:
        if not any(np.max(np.abs(q - r)) < tol_rad for r in reps):
            reps.append(q)
    if len(reps) < min_distinct:
        recs = ", ".join(str(int(r)) for r in records)
        raise RobocalError(f"{where(path, MEASUREMENT_CHANNEL)}: records {recs}: degenerate pose set — only "
                           f"{len(reps)} distinct robot pose(s) (within {tol_rad} rad); need at least {min_distinct} "
                           f"differing poses to separate hand-eye from camera parameters")


def load(rec, joint_offsets: bool = False) -> tuple[ScannerModel, dict[str, np.ndarray]]:
    """Measurement model and table of a scanner recording (bounds and image size from its
    metadata when present, else Table 2 and 640x480)."""
    from pipeline.errors import RobocalError
    from pipeline.recording.schemas import META_ROBOT

    try:
        arm = SerialArm.from_dict(rec.meta(META_ROBOT))
    except (KeyError, ValueError, TypeError) as e:
        raise RobocalError(f"{rec.path}: robot model metadata is malformed ({e})") from None
    meta = rec.metadata.get(META_SCANNER, {})
    lo, hi = bounds()
    try:
        if "bounds" in meta:
            lo = np.array([float(meta["bounds"][n][0]) for n in cam.SCANNER_NAMES])
            hi = np.array([float(meta["bounds"][n][1]) for n in cam.SCANNER_NAMES])
        nominal = (np.array([float(meta["nominal"][n]) for n in cam.SCANNER_NAMES]) if "nominal" in meta
                   else 0.5 * (lo + hi))
    except (KeyError, ValueError, TypeError, IndexError) as e:
        raise RobocalError(f"{rec.path}: metadata {META_SCANNER!r} is malformed ({e})") from None
    table = stripe_table(rec)
    if table["joint_positions"].shape[1] != arm.n_joints:
        raise RobocalError(f"{rec.path}: channel {MEASUREMENT_CHANNEL}: observations have "
                           f"{table['joint_positions'].shape[1]} joint values, the robot model has {arm.n_joints}")
    first = np.unique(table["pose"], return_index=True)[1]
    check_pose_set(rec.path, table["joint_positions"][first], table["record"][first])
    size = (int(meta.get("image_width_px", IMAGE_SIZE_PX[0])), int(meta.get("image_height_px", IMAGE_SIZE_PX[1])))
    model = ScannerModel(arm=arm, nominal_x=tuple(nominal), joint_offsets=joint_offsets, image_size=size,
                         lower=tuple(lo), upper=tuple(hi))
    return model, table
