"""Terms of a touch sensor (the welding wire as a probe): where the trigger fires relative to contact.

- ``trigger_pretravel`` (m): the trigger fires after the wire has travelled d past contact along the
  search direction (−face normal): the tip, as the model should place it, is d back along the face
  normal from the latch;
- ``trigger_latency`` (s): the encoders latch t_l after contact while the arm moves at its approach
  velocity: the contact was where the arm was t_l earlier.  Its look-alike is the pretravel; when the
  approach speed hardly varies (`MIN_SPEED_SPREAD`) the two cannot be told apart and the latency is
  marked ``blocked``.

Tip bases (n, 3, 1) in the jig frame {W}.
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.library.term import Effect, Table
from pipeline.models import serial_arm
from pipeline.models.serial_arm import SerialArm

PLAUSIBLE = {"trigger_pretravel": 2e-3, "trigger_latency": 0.05}  # m, s
ADVICE = {
    "trigger_pretravel": "touch faces whose normals point in opposite directions",
    "trigger_latency": "vary the search speed (e.g. 5, 10 and 20 mm/s)",
}
MIN_SPEED_SPREAD = 1.5  # approach speeds must span this ratio for latency to be told from pretravel


def tip_speed_vector(x: np.ndarray, table: Table) -> np.ndarray:
    """Tip velocity (n,3) m/s in {W} just before each contact: J_q · q̇_approach."""
    _, Jq = serial_arm.joint_jacobian(x, table["joint_positions"])
    return np.einsum("nij,nj->ni", Jq, table["approach_joint_velocity"])


def _pretravel(arm, x, t):
    """Tip, as the model should place it, is d back along the face normal from the latch."""
    sign = np.asarray(t["normal_sign"], float)
    n = sign.size
    D = np.zeros((n, 3, 1))
    D[np.arange(n), np.asarray(t["axis"], int), 0] = sign
    return D


def _latency(arm, x, t):
    """The encoders latch t_l late: the contact was where the arm was t_l earlier."""
    return -tip_speed_vector(x, t)[:, :, None]


def pretravel() -> Effect:
    return Effect("trigger_pretravel", "touch sensor", ("pretravel",), ("m",), PLAUSIBLE["trigger_pretravel"], "tip",
                  _pretravel, 80, "approach", ADVICE["trigger_pretravel"])


def latency(arm: SerialArm, table: Table) -> Effect:
    """trigger_latency, blocked (absorbed by the pretravel) when the approach speed's 90th/10th
    percentile ratio is below `MIN_SPEED_SPREAD`."""
    speed = np.linalg.norm(tip_speed_vector(arm.vector(), table), axis=1) if "approach_joint_velocity" in table else None
    spread = float(np.percentile(speed, 90) / max(np.percentile(speed, 10), 1e-12)) if speed is not None else 1.0
    blocked = {} if spread >= MIN_SPEED_SPREAD else {
        "blocked": f"the approach speed hardly varies (90th/10th percentile ratio {spread:.2f}): latency acts "
                   f"like pretravel", "absorbed_by": "trigger_pretravel"}
    return Effect("trigger_latency", "touch sensor", ("latency",), ("s",), PLAUSIBLE["trigger_latency"], "tip",
                  _latency, 85, "approach", ADVICE["trigger_latency"], confounders=("trigger_pretravel",), data=blocked)
