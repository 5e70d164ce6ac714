"""Seed 003: Delta parallel robot measured with a laser tracker.

Each `/tracker/point` record gives the actuator angles θ (3,) rad and the reflector position
p_T (3,) m in the tracker frame {T}.  Residual (3 per record, m, in the base frame {A},
seed eqs. 12–15):

    r = M(β, θ) − (ᴬR_T p_T + ᴬt_T),       M = P(β, θ) + R_P·(0, 0, −h_M)

with P the platform point from the analytic forward kinematics (simplified model β',
R_P = I) or the Newton solution of the full model (variant "extended").  Parameters: the
error parameters leg by leg, then the registration ``tracker.x,y,z`` (m) and
``tracker.rz,ry,rx`` (rad; ᴬR_T = Rz·Ry·Rx), then ``reflector.h`` (m).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.errors import RobocalError, where
from pipeline.identify.model import Table
from pipeline.models import delta as dm
from pipeline.models.delta import Delta
from pipeline.models.transforms import rot

SYSTEM = "delta-tracker"
MEASUREMENT_CHANNEL = "/tracker/point"
REG_KEYS = ("tracker.x", "tracker.y", "tracker.z", "tracker.rz", "tracker.ry", "tracker.rx")
H_NOMINAL = 0.050  # reflector (SMR centre) below the platform point P, m
VARIANTS = ("simplified", "extended")


# ----- registration {T} -> {A} ----------------------------------------------------------
def registration_matrix(reg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ᴬR_T (3, 3) and ᴬt_T (3,) m of registration parameters (x, y, z, rz, ry, rx)."""
    reg = np.asarray(reg, float)
    cz, sz, cy, sy, cx, sx = np.cos(reg[3]), np.sin(reg[3]), np.cos(reg[4]), np.sin(reg[4]), np.cos(reg[5]), np.sin(reg[5])
    R = np.array([[cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
                  [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
                  [-sy, cy * sx, cy * cx]])
    return R, reg[:3].copy()


def register(p_a: np.ndarray, p_t: np.ndarray) -> np.ndarray:
    """Closed-form rigid registration (Kabsch, via `Rotation.align_vectors`) of tracker points
    p_t (N, 3) onto base-frame points p_a (N, 3), N ≥ 4 (seed eq. 14): parameters
    (x, y, z, rz, ry, rx) with p_a ≈ ᴬR_T p_t + ᴬt_T.  ValueError if N < 4 or the points are
    collinear."""
    p_a, p_t = np.asarray(p_a, float), np.asarray(p_t, float)
    if p_t.shape[0] < 4:
        raise ValueError(f"the registration needs at least 4 points, got {p_t.shape[0]}")
    ca, ct = p_a.mean(axis=0), p_t.mean(axis=0)
    s = np.linalg.svd(p_t - ct, compute_uv=False)
    if s[1] <= 1e-9 * max(s[0], 1e-12):
        raise ValueError("the registration points are collinear (rotation undetermined)")
    rotation, _ = Rotation.align_vectors(p_a - ca, p_t - ct)
    R = rotation.as_matrix()
    rz, ry, rx = Rotation.from_matrix(R).as_euler("ZYX")
    return np.array([*(ca - R @ ct), rz, ry, rx])


def _rotation_derivatives(reg: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """dᴬR_T/drz, /dry, /drx (each 3×3) for ᴬR_T = Rz·Ry·Rx."""
    rz, ry, rx = reg[3:]
    Rz, Ry, Rx = rot("z", rz), rot("y", ry), rot("x", rx)
    dRz = np.array([[-np.sin(rz), -np.cos(rz), 0], [np.cos(rz), -np.sin(rz), 0], [0, 0, 0]])
    dRy = np.array([[-np.sin(ry), 0, np.cos(ry)], [0, 0, 0], [-np.cos(ry), 0, -np.sin(ry)]])
    dRx = np.array([[0, 0, 0], [0, -np.sin(rx), -np.cos(rx)], [0, np.cos(rx), -np.sin(rx)]])
    return dRz @ Ry @ Rx, Rz @ dRy @ Rx, Rz @ Ry @ dRx


def _registration_jacobian(reg: np.ndarray, p_t: np.ndarray) -> np.ndarray:
    """d(ᴬR_T p_t + ᴬt_T)/d(x, y, z, rz, ry, rx), (N, 3, 6)."""
    J = np.zeros((p_t.shape[0], 3, 6))
    J[:, :, :3] = np.eye(3)
    for k, dR in enumerate(_rotation_derivatives(reg)):
        J[:, :, 3 + k] = p_t @ dR.T
    return J


# ----- the measurement model -------------------------------------------------------------
@dataclass(frozen=True)
class TrackerModel:
    """Laser-tracker measurement model of a Delta robot (implements `MeasurementModel`).

    Data columns: ``joint_positions`` (n, 3) actuator angles rad, ``point`` (n, 3) m in {T};
    optional ``record`` (message index), ``timestamp_ns``.
    """

    delta: Delta = field(default_factory=Delta)
    h_nominal: float = H_NOMINAL
    variant: str = "simplified"
    system: str = SYSTEM
    residual_dim: int = 3

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise ValueError(f"unknown Delta model variant {self.variant!r} (use one of {VARIANTS})")

    @property
    def extended(self) -> bool:
        return self.variant == "extended"

    @property
    def n_beta(self) -> int:
        return 36 if self.extended else 27

    def parameter_names(self) -> list[str]:
        return dm.beta_names(3, self.extended) + list(REG_KEYS) + ["reflector.h"]

    def parameter_units(self) -> list[str]:
        return dm.beta_units(3, self.extended) + ["m", "m", "m", "rad", "rad", "rad", "m"]

    def nominal(self) -> np.ndarray:
        x = np.zeros(self.n_beta + 7)
        x[-1] = self.h_nominal
        return x

    def priority(self) -> np.ndarray:
        """Registration first (it defines where {A} is seen from the tracker), then the
        actuator offsets and link lengths (and the extended terms), then the base joints of
        legs 2 and 3; leg 1's base joint comes after (a translation of {A} is the same as the
        registration's translation), the platform joints after that (Δb_i − Δa_i is all that
        enters), the reflector offset last (it only shifts z, like tracker.z, while R_P = I)."""
        def level(n: str) -> int:
            if n.startswith("tracker."):
                return 0
            leg, key = n.split(".")
            if key.startswith("da_"):
                return 3 if leg == "leg1" else 2
            if key.startswith("db_"):
                return 4
            if n == "reflector.h":
                return 5
            return 1
        return np.array([level(n) for n in self.parameter_names()])

    # -- pieces
    def _split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        x = np.asarray(x, float)
        return x[: self.n_beta], x[self.n_beta: self.n_beta + 6], float(x[-1])

    def _simplified_beta(self, beta: np.ndarray) -> np.ndarray:
        return dm.split(beta, self.extended)[0].ravel()

    def reflector(self, x: np.ndarray, theta: np.ndarray, jac: bool = False):
        """Reflector position M in {A} (n, 3) m; with jac, also dM/dx (n, 3, P) (zero on the
        registration columns)."""
        beta, _, h = self._split(x)
        theta = np.atleast_2d(np.asarray(theta, float))
        n = theta.shape[0]
        offset = np.array([0.0, 0.0, -h])
        if self.extended:
            p, R, _ = dm.full_forward(self.delta, beta, theta, extended=True)
            M = p + R @ offset
            if not jac:
                return M
            Jb, ez = dm.full_jacobian(self.delta, beta, theta, p, R, offset, extended=True)
            J = np.zeros((n, 3, self.n_beta + 7))
            J[:, :, : self.n_beta] = Jb
            J[:, :, -1] = -ez
            return M, J
        b = self._simplified_beta(beta)
        p, _ = dm.forward(self.delta, b, theta)
        M = p + offset
        if not jac:
            return M
        J = np.zeros((n, 3, self.n_beta + 7))
        J[:, :, :27] = dm.forward_jacobian(self.delta, b, theta, p)
        J[:, 2, -1] = -1.0
        return M, J

    # -- MeasurementModel
    def residuals(self, x: np.ndarray, data: Table) -> np.ndarray:
        _, reg, _ = self._split(x)
        R, t = registration_matrix(reg)
        return self.reflector(x, data["joint_positions"]) - (np.asarray(data["point"]) @ R.T + t)

    def jacobian(self, x: np.ndarray, data: Table) -> np.ndarray:
        _, reg, _ = self._split(x)
        _, J = self.reflector(x, data["joint_positions"], jac=True)
        J[:, :, self.n_beta: self.n_beta + 6] = -_registration_jacobian(reg, np.asarray(data["point"], float))
        return J

    def points(self, x: np.ndarray, data: Table) -> tuple[np.ndarray, np.ndarray]:
        """Platform point P seen in the tracker (workcell) frame {T}, ᵀP = ᴬR_Tᵀ(ᴬP − ᴬt_T),
        (n, 3) m, and dᵀP/dx (n, 3, P).  In {T} the prediction does not depend on the arbitrary
        choice of origin of {A} (leg 1's base joint), so its covariance is the accuracy a user
        gets when commanding positions in the workcell."""
        beta, reg, _ = self._split(x)
        theta = np.atleast_2d(np.asarray(data["joint_positions"], float))
        J = np.zeros((theta.shape[0], 3, self.n_beta + 7))
        if self.extended:
            p, Rp, _ = dm.full_forward(self.delta, beta, theta, extended=True)
            J[:, :, : self.n_beta], _ = dm.full_jacobian(self.delta, beta, theta, p, Rp, np.zeros(3), True)
        else:
            b = self._simplified_beta(beta)
            p, _ = dm.forward(self.delta, b, theta)
            J[:, :, :27] = dm.forward_jacobian(self.delta, b, theta, p)
        R, t = registration_matrix(reg)
        rel = p - t
        J = np.einsum("ji,njk->nik", R, J)  # Rᵀ · dP/dx
        J[:, :, self.n_beta: self.n_beta + 3] = -R.T
        for k, dR in enumerate(_rotation_derivatives(reg)):
            J[:, :, self.n_beta + 3 + k] = rel @ dR  # (dR)ᵀ rel, row-wise
        return rel @ R, J

    def initial_guess(self, data: Table) -> np.ndarray:
        """Nominal β' with the registration from the closed-form fit of the nominal-model
        reflector positions to the tracker points (seed eq. 14; ≥ 4 points)."""
        x = self.nominal()
        x[self.n_beta: self.n_beta + 6] = register(self.reflector(x, data["joint_positions"]), data["point"])
        return x

    def uncalibrated(self, data: Table) -> np.ndarray:
        """Before calibration: the nominal Delta seen through the closed-form registration
        (without it no tracker point can be compared with the robot)."""
        return self.initial_guess(data)

    def describe(self, x: np.ndarray) -> dict:
        """Robot model JSON: the nominal Delta plus the identified error parameters."""
        beta, reg, h = self._split(x)
        names = dm.beta_names(3, self.extended)
        keys = dm.LEG_KEYS + (dm.EXT_KEYS if self.extended else ())
        legs = [{"phi": float(self.delta.phi[i]),
                 **{k: float(beta[names.index(f"leg{i + 1}.{k}")]) for k in keys}} for i in range(3)]
        return {**self.delta.to_dict(), "error_model": self.variant, "legs": legs,
                "tracker_registration": dict(zip(("x", "y", "z", "rz", "ry", "rx"), map(float, reg))),
                "reflector_offset_m": h}

    # -- validation metric of seed 003 Fig. 6
    def distance_ratios(self, x: np.ndarray, data: Table) -> np.ndarray:
        """Computed / measured distance between consecutive (neighbouring) points, (n−1,).
        Independent of the registration: measured distances are taken in {T}."""
        M = self.reflector(x, data["joint_positions"])
        P = np.asarray(data["point"], float)
        return np.linalg.norm(np.diff(M, axis=0), axis=1) / np.linalg.norm(np.diff(P, axis=0), axis=1)

    def extra_metrics(self, x_before: np.ndarray, x_after: np.ndarray, data: Table) -> dict:
        """Seed 003's validation (Fig. 6): distance ratio of neighbouring points before/after."""
        rb, ra = self.distance_ratios(x_before, data), self.distance_ratios(x_after, data)
        amp_b, amp_a = float(np.max(np.abs(rb - 1))), float(np.max(np.abs(ra - 1)))
        return {"distance_ratio": {
            "note": "computed (forward kinematics) / measured (tracker) distance between consecutive "
                    "measurement points, as seed 003 Fig. 6; 1 is perfect",
            "before": rb.tolist(), "after": ra.tolist(),
            "std_before": float(np.std(rb - 1)), "std_after": float(np.std(ra - 1)),
            "max_abs_dev_before": amp_b, "max_abs_dev_after": amp_a,
            "amplitude_reduction": 1 - amp_a / amp_b if amp_b > 0 else 0.0,
        }}


# ----- recordings ------------------------------------------------------------------------
def tracker_points(rec) -> dict[str, np.ndarray]:
    """`/tracker/point` as columns: timestamp_ns, joint_positions (n, 3) rad, point (n, 3) m,
    sigma (n,) m (only if some record has it; NaN where absent), record.  Every bad record is named."""
    msgs = rec.require(MEASUREMENT_CHANNEL)
    n = len(msgs)
    out = {"timestamp_ns": np.empty(n, np.int64), "joint_positions": np.empty((n, 3)), "point": np.empty((n, 3)),
           "sigma": np.full(n, np.nan), "record": np.arange(n)}
    nan_records: list[int] = []
    for i, m in enumerate(msgs):
        for key in ("timestamp_ns", "joint_positions", "point"):
            if key not in m:
                raise RobocalError(f"{where(rec.path, MEASUREMENT_CHANNEL, i)}: field {key!r} missing")
        for key in ("joint_positions", "point"):
            try:
                v = np.asarray([np.nan if e is None else e for e in m[key]], dtype=float)
            except (TypeError, ValueError):
                raise RobocalError(f"{where(rec.path, MEASUREMENT_CHANNEL, i)}: field {key!r} is not a list "
                                   "of numbers") from None
            if v.shape != (3,):
                raise RobocalError(f"{where(rec.path, MEASUREMENT_CHANNEL, i)}: field {key!r} has {v.size} "
                                   "values, expected 3")
            if not np.all(np.isfinite(v)):
                nan_records.append(i)
            out[key][i] = v
        out["timestamp_ns"][i] = int(m["timestamp_ns"])
        if m.get("sigma") is not None:
            out["sigma"][i] = float(m["sigma"])
    if np.all(np.isnan(out["sigma"])):
        del out["sigma"]
    if nan_records:
        recs = ", ".join(map(str, sorted(set(nan_records))[:20]))
        raise RobocalError(f"{rec.path}: channel {MEASUREMENT_CHANNEL}: records {recs}: point or joint_positions "
                           "has NaN or inf (tracker lost the reflector?); drop these records")
    return out


def check_table(path, model: TrackerModel, table: dict[str, np.ndarray]) -> None:
    """Input errors that would stop a calibration, as one-line `RobocalError`s naming records."""
    n = table["point"].shape[0]
    if n < 4:
        raise RobocalError(f"{where(path, MEASUREMENT_CHANNEL)}: only {n} tracker points; the registration of "
                           "the tracker frame needs at least 4")
    _, ok = dm.forward(model.delta, np.zeros(27), table["joint_positions"])
    if not np.all(ok):
        bad = table.get("record", np.arange(n))[~ok]
        recs = ", ".join(map(str, bad[:20]))
        raise RobocalError(f"{where(path, MEASUREMENT_CHANNEL)}: records {recs}: actuator angles outside the "
                           "workspace (forward kinematics has no real root: the legs cannot close)")
    try:
        register(model.reflector(model.nominal(), table["joint_positions"]), table["point"])
    except ValueError as e:
        raise RobocalError(f"{where(path, MEASUREMENT_CHANNEL)}: {e}") from None


def load(rec, variant: str = "simplified") -> tuple[TrackerModel, dict[str, np.ndarray]]:
    """Measurement model and table of a Delta + laser-tracker recording."""
    from pipeline.recording.schemas import META_FIXTURE, META_ROBOT

    try:
        delta = Delta.from_dict(rec.meta(META_ROBOT))
        fixture = rec.metadata.get(META_FIXTURE, {})
        h = float(fixture.get("reflector_offset_m", H_NOMINAL))
    except (KeyError, ValueError, TypeError) as e:
        raise RobocalError(f"{rec.path}: robot model or fixture metadata is malformed ({e})") from None
    model = TrackerModel(delta, h, variant)
    table = tracker_points(rec)
    check_table(rec.path, model, table)
    return model, table
