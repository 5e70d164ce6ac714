"""Seed 000: touch-sensing arc-welding arm.  Reference models and the touch measurement model.

A contact on a face that fixes jig coordinate `axis` gives one residual:
``r = p_axis(x, q) − coordinate`` (m), with p the tool tip in the jig frame {W}.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.identify.model import Table
from pipeline.measurements.plane import PlaneModel
from pipeline.models.serial_arm import Joint, LinkMass, SerialArm

SYSTEM = "arc-welder"
MEASUREMENT_CHANNEL = "/touch/contact"
MM, DEG = 1e-3, np.pi / 180

# (theta_offset, alpha, d, a, beta) in deg/mm: seed 000 Table 2 (the paper's nominal model)
_NOMINAL = [(0, -90, 0, 0, 0), (-90, 0, 0, 350, 0), (0, -90, 80, 0, 0),
            (0, 90, 350, 0, 0), (0, -90, -60, 0, 0), (0, 0, 0, 0, 0)]
_TRUTH = [(0, -90.216, 0, 0, -0.007), (-91.337, 1.199, 0, 354.447, 0.123), (0.536, -90.742, 80, 0, 0),
          (0.710, 89.291, 353.239, 1.821, 0), (0.307, -89.705, -60, 0, 0), (0, 0, 0, 0, 0)]
_LIMITS_DEG = [(-170, 170), (-150, 150), (-170, 170), (-190, 190), (-135, 135), (-360, 360)]


def _arm(table, base, tool, name) -> SerialArm:
    joints = tuple(
        Joint(name=f"J{i + 1}", theta_offset=t * DEG, alpha=al * DEG, d=d * MM, a=a * MM, beta=b * DEG,
              lower=lo * DEG, upper=hi * DEG)
        for i, ((t, al, d, a, b), (lo, hi)) in enumerate(zip(table, _LIMITS_DEG)))
    bx, by, bz, rz, rx, ry = base
    tx, ty, tz, trz, tr_y, trx = tool
    # lumped masses (kg, link-frame centre of mass, m): a 6 kg-payload arc-welding arm
    masses = (LinkMass(1, 9.0, (-0.175, 0.0, 0.0)), LinkMass(2, 4.0, (0.0, 0.0, 0.0)),
              LinkMass(3, 5.0, (0.0, -0.175, 0.0)), LinkMass(5, 3.0, (0.0, 0.0, 0.15)))
    return SerialArm(name=name,
                     base={"x": bx * MM, "y": by * MM, "z": bz * MM, "rz": rz * DEG, "rx": rx * DEG, "ry": ry * DEG},
                     joints=joints,
                     tool={"x": tx * MM, "y": ty * MM, "z": tz * MM, "rz": trz * DEG, "ry": tr_y * DEG, "rx": trx * DEG},
                     masses=masses)


def nominal_arm() -> SerialArm:
    """Nominal model of seed 000 Table 2."""
    return _arm(_NOMINAL, (340, 740, 350, -90, 0, 0), (0, 0, 410, 0, -18, 0), "arc-welder nominal")


def reference_truth() -> SerialArm:
    """Default simulator truth: the paper's calibrated column of Table 2 (tool ry = −18°)."""
    return _arm(_TRUTH, (339.106, 740.678, 351.276, -92.350, 0.128, -0.244), (-2.895, 7.636, 411.267, 0, -18, 0),
                "arc-welder truth (seed 000 Table 2)")


def random_truth(nominal: SerialArm, rng: np.random.Generator) -> SerialArm:
    """A truth with errors of the paper's size: ~1° angles, ~3 mm lengths, ~2° base yaw."""
    x = nominal.vector().copy()
    units = np.array(nominal.parameter_units())
    names = nominal.parameter_names()
    ang = units == "rad"
    x[ang] += rng.normal(0, 0.7 * DEG, ang.sum())
    x[~ang] += rng.normal(0, 2.0 * MM, (~ang).sum())
    x[names.index("base.rz")] += rng.choice([-1, 1]) * rng.uniform(1.5, 2.5) * DEG
    # tool orientation has no effect on a point tool tip; keep it nominal
    for k in ("tool.rz", "tool.ry", "tool.rx"):
        x[names.index(k)] = nominal.vector()[names.index(k)]
    return nominal.with_vector(x)


@dataclass(frozen=True)
class TouchModel(PlaneModel):
    """Seed 000's touch jig as a composition: the plane-contact measurement type over the D-H +
    Hayati arm (`kin`, a `SerialArm`), each contact's plane a known jig face (implements
    `MeasurementModel`).

    Data columns: ``joint_positions`` (n, n_joints) rad, ``axis`` (n,) int 0/1/2 (the face's
    normal), ``coordinate`` (n,) m (the face's jig coordinate).
    """

    system = SYSTEM
    fit_tool: bool = True

    @property
    def arm(self) -> SerialArm:
        return self.kin

    def priority(self) -> np.ndarray:
        """Which member of a dependent group is kept: base and tool translation first, then
        the D-H terms, Hayati's β last (only where the D-H terms cannot do)."""
        def level(n: str) -> int:
            if n.startswith("base.") or n in ("tool.x", "tool.y", "tool.z"):
                return 0
            return 2 if n.endswith(".beta") else 1
        return np.array([level(n) for n in self.parameter_names()])

    def row_planes(self, x: np.ndarray, data: Table):
        """Each contact's face: normal e_axis, offset its jig coordinate (known planes)."""
        ax = np.asarray(data["axis"], int)
        zeros = np.zeros((len(ax), 3))
        return np.eye(3)[ax], np.asarray(data["coordinate"], float), np.full(len(ax), -1), zeros, zeros

    def exports(self, x: np.ndarray) -> dict[str, str]:
        """The calibrated arm as a URDF (link `jig` → `tool`) and as a D-H table."""
        from pipeline.models.dh_export import dh_table_csv, to_urdf

        arm = self.arm.with_vector(x)
        return {"model.urdf": to_urdf(arm), "dh_table.csv": dh_table_csv(arm)}


# ----- recordings ------------------------------------------------------------------------
def contact_messages(sim, names: list[str] | None = None) -> list[tuple[str, dict]]:
    """`/touch/contact` message bodies of a simulated campaign."""
    axes = "xyz"
    return [("/touch/contact", {"timestamp_ns": int(t), "joint_positions": q, "face": f, "axis": axes[a],
                                "coordinate": float(c)})
            for t, q, f, a, c in zip(sim.contact_t_ns, sim.contact_q.tolist(), sim.contact_face,
                                     sim.contact_axis, sim.contact_coordinate)]


def load(rec) -> tuple[TouchModel, dict[str, np.ndarray]]:
    """Measurement model and measurement table of an arc-welder recording."""
    from pipeline.errors import RobocalError
    from pipeline.ingest.streams import contacts
    from pipeline.models.jig import Jig
    from pipeline.recording.schemas import META_FIXTURE, META_ROBOT

    try:
        arm = SerialArm.from_dict(rec.meta(META_ROBOT))
        jig = Jig.from_dict(rec.meta(META_FIXTURE))  # a recording must carry its fixture
    except (KeyError, ValueError, TypeError) as e:
        raise RobocalError(f"{rec.path}: robot model or fixture metadata is malformed ({e})") from None
    table = contacts(rec)
    known = {f.id for f in jig.faces}
    unknown = [i for i, f in enumerate(table["face"]) if f not in known]
    if unknown:  # the fixture must describe every face touched (diagnose needs its normal)
        raise RobocalError(f"{rec.path}: channel /touch/contact: records {', '.join(map(str, unknown[:5]))}"
                           f"{' …' if len(unknown) > 5 else ''}: face {table['face'][unknown[0]]!r} is not in "
                           f"the fixture metadata {META_FIXTURE!r} (faces: {', '.join(sorted(known)) or 'none'})")
    if table["joint_positions"].shape[1] != arm.n_joints:
        raise RobocalError(f"{rec.path}: channel /touch/contact: contacts have {table['joint_positions'].shape[1]} "
                           f"joint values, the robot model has {arm.n_joints} joints")
    return TouchModel(arm), table
