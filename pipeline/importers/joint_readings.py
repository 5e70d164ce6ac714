"""Raw joint position readings → the URDF's joint angles: what a log's position columns are when they
are not joint angles already (motor-side encoder angles, a coupled wrist, another zero).

A controller may log each *motor's* angle: the joint turns 1/N of it through a reduction N, and in a
coupled wrist one motor turns two joints (a Stäubli's sixth motor turns through joints 5 and 6:
θ6 = N6·(q5 + q6)).  The importer's words (``--position-scale``, ``--position-mix``,
``--position-offset``) declare the conversion per joint J::

    q_J = k_J · Σ_K f_JK · p_K + c_J            (rad; m for a prismatic joint)

with p the raw readings, `scale` k (rad per raw unit, default 1: ``1/32`` for a 32:1 reduction read on the
motor side, negative for a reversed one), `mix` f (default f_JJ = 1: the readings joint J combines
before scaling, e.g. ``joint_6=joint_6-32/45*joint_5``), `offset` c (the joint's zero, e.g. ``-pi/2``).
Logged velocities convert with k·f alone.  The declaration is kept in the recording's campaign
(``positions``) beside the effort's; the recording's stream holds joint angles.  Pure: `declaration`
reads the words, `convert` applies them, vectorised.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.dynamics import effort as E
from pipeline.errors import RobocalError


@dataclass(frozen=True)
class PositionSpec:
    """The position declaration in the command line's words: `scale` ``JOINT=K`` (rad or m per raw unit,
    ``1/32`` allowed), `offset` ``JOINT=C`` (rad or m, ``-pi/2`` allowed), `mix` ``JOINT=EXPR``."""

    scale: tuple[str, ...] = ()
    offset: tuple[str, ...] = ()
    mix: tuple[str, ...] = ()


def declaration(spec: PositionSpec, joints: list[str]) -> dict | None:
    """The campaign's ``positions`` document {scale, offset, mix} (joint names → numbers), or None when
    the readings are joint positions already."""
    scale = E.parse_pairs("--position-scale", list(spec.scale), joints)
    offset = E.parse_pairs("--position-offset", list(spec.offset), joints)
    mix = E.parse_mix(list(spec.mix), joints, "--position-mix", "joint_6=joint_6-32/45*joint_5")
    if any(v == 0 for v in scale.values()):
        raise RobocalError("--position-scale: a scale of 0 leaves the joint without a position")
    if not (scale or offset or mix):
        return None
    doc = {"scale": scale, "offset": offset, "mix": mix}
    check_invertible(doc, joints, "--position-mix")
    return doc


def matrix(doc: dict | None, joints: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(M (J, J), c (J,)) with q = M p + c for raw readings p in `joints` order (identity when `doc` is None)."""
    if not doc:
        return np.eye(len(joints)), np.zeros(len(joints))
    return E.scaled_mix(doc, joints, default_scale=1.0)


def check_invertible(doc: dict | None, joints: list[str], where_: str) -> None:
    """One line when the conversion maps two different sets of readings to the same joint angles (its matrix
    is singular: a mix that repeats another joint's row, or drops a reading every joint needs) — the joints'
    angles could not have come from the motors."""
    if not doc:
        return
    M, _ = matrix(doc, joints)
    sv = np.linalg.svd(M, compute_uv=False)
    if sv[-1] <= 1e-9 * sv[0]:
        raise RobocalError(f"{where_}: the position conversion (--position-scale / --position-mix) is singular: two "
                           "joints' angles would be the same combination of the readings")


def convert(doc: dict | None, joints: list[str], p: np.ndarray, v: np.ndarray | None = None):
    """(q (T, J), v (T, J) or None): joint positions and velocities of raw readings p (T, J), v (T, J)."""
    if not doc:
        return p, v
    M, c = matrix(doc, joints)
    return p @ M.T + c, (None if v is None else v @ M.T)


def coupled_motors(doc: dict | None, joints: list[str]) -> tuple[tuple[str, tuple[float, ...]], ...]:
    """The readings that move several joints (a coupled wrist's motor): for each, (the joint whose column it
    is, G (J,)) with the motor's speed u = G·q̇ in that joint's units (G_K = 1 for its own joint K) — its
    friction and rotor inertia act on u and reach joint j's torque as G_j times theirs (the transmission's
    transpose: τ = Mᵀ⁻¹ τ_motor).  Empty when every reading is one joint's."""
    if not doc or not doc.get("mix"):
        return ()
    M, _ = matrix(doc, joints)
    inv = np.linalg.inv(M)
    out = []
    for k, row in enumerate(inv):
        nz = np.abs(row) > 1e-9 * np.abs(row).max()
        if nz.sum() > 1:
            g = row / (row[k] if nz[k] else row[np.argmax(np.abs(row))])
            out.append((joints[k], tuple(float(x) if abs(x) > 1e-12 else 0.0 for x in g)))
    return tuple(out)
