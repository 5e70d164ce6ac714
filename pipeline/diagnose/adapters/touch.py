"""The arc-welder touch campaign's diagnosis adapter (library, signatures, lack-of-fit variables)."""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.adapters import touch_variables
from pipeline.diagnose.adapters.adapter import Adapter
from pipeline.diagnose.library.term import Effect, signature
from pipeline.diagnose.library.touch import touch_library
from pipeline.diagnose.library.touch_probe import tip_speed_vector
from pipeline.diagnose.verdict import lack_of_fit
from pipeline.diagnose.verdict.checks import touch_floor_variance
from pipeline.models import serial_arm


def touch_adapter(model, table, jig_tolerance_m: float = 2e-5, library: list[Effect] | None = None,
                  repeatability_3sigma_m: float | None = None) -> Adapter:
    """The arc-welder touch campaign's adapter (`library.touch.touch_library`, joint/time/speed lack of fit);
    with the robot's declared repeatability, the noise floor (`verdict.checks.touch_floor_variance`)."""
    arm = model.arm
    lib = library if library is not None else touch_library(arm, table, jig_tolerance_m)
    jn = [j.name for j in arm.joints]

    def sigs(x, data, effects):
        _, Jq = serial_arm.joint_jacobian(x, data["joint_positions"])
        return [signature(e, arm, x, data, Jq)[:, None, :] for e in effects]

    def variables(x):
        speed = None
        if "approach_joint_velocity" in table:
            speed = np.linalg.norm(tip_speed_vector(x, table), axis=1)
        return lack_of_fit.touch_variables(x, table, jn, speed) + touch_variables.touch_extra(x, table, jn)

    def located(e: Effect):
        if e.name == "backlash" and e.location in jn:
            return f"last motion sign of {e.location}", np.asarray(table["last_motion_sign"])[:, jn.index(e.location)]
        if e.variable.startswith("q_") and e.variable[2:] in jn:
            return f"{e.variable[2:]} (rad)", np.asarray(table["joint_positions"])[:, jn.index(e.variable[2:])]
        if e.variable == "time":
            return "time since start (s)", np.asarray(table["time_since_start_s"], float)
        if e.variable.startswith("temperature_rise_K") and e.variable in table:
            return (f"temperature rise of {e.location.removeprefix('temperature ')} (K)",
                    np.asarray(table[e.variable], float))
        if e.variable == "approach" and "approach_joint_velocity" in table:
            return "approach speed (m/s)", np.linalg.norm(tip_speed_vector(arm.vector(), table), axis=1)
        if e.variable == "face":
            faces = np.asarray(table["face"]).astype(str)
            return f"on face {e.location} (1) or not (0)", (faces == e.location).astype(float)
        return None

    # each face's machining error is shared by its contacts: uniform within ± the jig tolerance
    faces = np.asarray(table["face"]).astype(str)
    Zf = (faces[:, None] == np.unique(faces)[None, :]).astype(float)
    floor = None
    if repeatability_3sigma_m is not None:
        def floor(x):
            _, Jq = serial_arm.joint_jacobian(x, table["joint_positions"])
            ax = np.asarray(table["axis"], int)
            return touch_floor_variance(Jq[np.arange(ax.size), ax], repeatability_3sigma_m, jig_tolerance_m)
    return Adapter(lib, sigs, variables, np.asarray(table["time_since_start_s"], float), located,
                   shared_error=(Zf, jig_tolerance_m**2 / 3), floor_variance=floor)
