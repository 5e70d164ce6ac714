"""The arc-welder touch campaign's catalogue: every candidate term of the library for a touch
diagnosis table (`adapters.touch_table`), in the order the selection breaks ties by.

Joint terms of every joint (`joint`: compliance, backlash, scale, eccentricity, transmission error),
the wrist couplings (six-joint arms), the thermal drift (`thermal`, one per temperature sensor), the
touch sensor's pretravel and latency (`touch_probe`), each face's offset (`jig`), then the couplings
of neighbouring joints, the growth of the links, the wire's stick-out (`wire`) and each face's tilt
and flatness.
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.library import jig, joint, thermal, touch_probe, wire
from pipeline.diagnose.library.term import Effect, Table, pick
from pipeline.models.serial_arm import SerialArm

MIN_ON_FACE = 8  # contacts a face needs for its tilt and flatness to be candidates


def touch_library(arm: SerialArm, table: Table, jig_tolerance_m: float = 2e-5) -> list[Effect]:
    """Every candidate term of the arc-welder touch campaign (module docstring); `jig_tolerance_m`
    the jig's machining tolerance (m), below which a face offset is immaterial."""
    nj = arm.n_joints
    lib: list[Effect] = []
    for family in (joint.compliance, joint.backlash, joint.scale, joint.eccentricity, joint.transmission_error):
        lib += [family(arm, j) for j in range(nj)]
    lib += [joint.backlash_play(arm, j, play, joint.play_column(play)) for play in joint.PLAY_RAD
            if joint.play_column(play) in table
            for j in range(nj)]
    if nj >= 6:
        lib += [joint.wrist_coupling(arm, src, dst) for src, dst in joint.WRIST_PAIRS]
    lib.append(thermal.thermal_drift_effect(table))
    lib += [thermal.sensor_drift(col, sensor) for col, sensor in thermal.temperature_columns(table)[1:]]
    lib.append(touch_probe.pretravel())
    lib.append(touch_probe.latency(arm, table))
    lib += [jig.offset(f, jig_tolerance_m) for f in sorted(set(np.asarray(table["face"]).astype(str)))]
    return lib + more_effects(arm, table)


def more_effects(arm: SerialArm, table: Table, min_on_face: int = MIN_ON_FACE) -> list[Effect]:
    """Couplings of neighbouring joints, link growth, wire stick-out, face tilt and flatness for a touch
    campaign's table (a table of face ids only — the simulator's look-up of a term by name — gets
    every candidate)."""
    lookup = "joint_positions" not in table
    min_on_face = 1 if lookup else min_on_face
    lib: list[Effect] = []
    for i, j in joint.NEIGHBOURS:
        if max(i, j) < arm.n_joints:
            lib += [joint.coupling(arm, i, j), joint.quadratic_coupling(arm, i, j)]
    if arm.n_joints >= 3:
        lib += [joint.coupling_difference(arm, i, j) for i, j in joint.DIFFERENCE_PAIRS]
    lib += thermal.growth_terms(arm, table, lookup)
    if "time_since_start_s" in table or lookup:
        lib.append(wire.stickout())
    faces, counts = np.unique(np.asarray(table["face"]).astype(str), return_counts=True)
    for f, c in zip(faces, counts):
        if c >= min_on_face:
            lib += [jig.tilt(str(f)), jig.flatness(str(f))]
    return lib


def effect_by_name(arm: SerialArm, table: Table, name: str, location: str | None,
                   jig_tolerance_m: float = 2e-5) -> Effect:
    """The library entry `name@location` (location may be omitted when unique); ``bump@JOINT:CENTRE_RAD``
    the out-of-library bump of `joint.bump`."""
    if name == "bump":
        j, _, c = (location or "").partition(":")
        names = [jj.name for jj in arm.joints]
        if j not in names:
            raise ValueError(f"bump needs @JOINT:CENTRE_RAD, e.g. bump=2e-4@J2:0.6 (got {location!r})")
        return joint.bump(arm, names.index(j), float(c or 0.0))
    return pick(touch_library(arm, table, jig_tolerance_m), name, location)
