"""The welding wire's stick-out: ``wire_stickout`` (m/s), the wire's free length grows by s·t along the
wire (the tool z axis, in the jig frame {W}; t the time since the start of the recording, s) — the
tool length varying from contact to contact as the wire is fed and burnt.  Tip basis (n, 3, 1) m per
unit."""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.library.term import Effect
from pipeline.models import serial_arm

PLAUSIBLE = 1e-6  # m/s
ADVICE = "cut the wire to length before each block and log it; vary the wire direction"


def _stickout(arm, x, t):
    F = serial_arm.frames(x, np.asarray(t["joint_positions"], float))
    wire = F[:, -1, :3, 2]  # the tool z axis in {W}
    return (np.asarray(t["time_since_start_s"], float)[:, None] * wire)[:, :, None]


def stickout() -> Effect:
    return Effect("wire_stickout", "wire", ("stickout_rate",), ("m/s",), PLAUSIBLE, "tip", _stickout,
                  76, "time", ADVICE)
