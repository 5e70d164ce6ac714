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

from pipeline.errors import RobocalError, where
from pipeline.identify.model import Table
from pipeline.measurements.registered_point import RegisteredPointModel
from pipeline.measurements.registration import register, registration_matrix  # noqa: F401 — this system's API
from pipeline.models import delta as dm
from pipeline.models.delta import Delta
from pipeline.models.delta_arm import VARIANTS, DeltaKinematics  # noqa: F401 — VARIANTS: this system's API

SYSTEM = "delta-tracker"
MEASUREMENT_CHANNEL = "/tracker/point"
REG_KEYS = ("tracker.x", "tracker.y", "tracker.z", "tracker.rz", "tracker.ry", "tracker.rx")
H_NOMINAL = 0.050  # reflector (SMR centre) below the platform point P, m


# ----- the measurement model: a composition ----------------------------------------------
@dataclass(frozen=True)
class TrackerModel(RegisteredPointModel):
    """Seed 003 as a composition: `DeltaKinematics` (β) + a point measured by a laser tracker
    registered to the base (``tracker.*``) + the reflector ``h`` m below the platform point.

    Data columns: ``joint_positions`` (n, 3) actuator angles rad, ``point`` (n, 3) m in {T};
    optional ``record`` (message index), ``timestamp_ns``.
    """

    kin: object = field(init=False, default=None)
    delta: Delta = field(default_factory=Delta)
    h_nominal: float = H_NOMINAL
    variant: str = "simplified"
    instrument: str = field(init=False, default="tracker")
    targets: tuple = field(init=False, default=())
    target_priority: int = field(init=False, default=5)

    system = SYSTEM

    def __post_init__(self) -> None:
        object.__setattr__(self, "kin", DeltaKinematics(self.delta, self.variant))
        object.__setattr__(self, "targets", (("reflector.h", (0.0, 0.0, -1.0), self.h_nominal),))

    @property
    def extended(self) -> bool:
        return self.kin.extended

    @property
    def n_beta(self) -> int:
        return self.kin.n_params

    def _split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        beta, reg, tv = self.parts(x)
        return beta, reg, float(tv[0])

    def _simplified_beta(self, beta: np.ndarray) -> np.ndarray:
        return self.kin.simplified_beta(beta)

    def reflector(self, x: np.ndarray, theta: np.ndarray, jac: bool = False):
        """Reflector position M in {A} (n, 3) m; with jac, also dM/dx (n, 3, P)."""
        return self.target_point(x, theta, jac)

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


def load(rec, variant: str | None = None) -> tuple[TrackerModel, dict[str, np.ndarray]]:
    """Measurement model and table of a Delta + laser-tracker recording.  The error model is
    `variant`, else the robot metadata's ``error_model`` (so every stage of a run uses the
    same one), else the simplified β'."""
    from pipeline.recording.schemas import META_FIXTURE, META_ROBOT

    try:
        robot = rec.meta(META_ROBOT)
        delta = Delta.from_dict(robot)
        fixture = rec.metadata.get(META_FIXTURE, {})
        h = float(fixture.get("reflector_offset_m", H_NOMINAL))
    except (KeyError, ValueError, TypeError) as e:
        raise RobocalError(f"{rec.path}: robot model or fixture metadata is malformed ({e})") from None
    variant = variant or robot.get("error_model") or "simplified"
    if variant not in VARIANTS:
        raise RobocalError(f"{rec.path}: robot model metadata: error_model {variant!r} is not one of {', '.join(VARIANTS)}")
    model = TrackerModel(delta, h, variant)
    table = tracker_points(rec)
    check_table(rec.path, model, table)
    return model, table
