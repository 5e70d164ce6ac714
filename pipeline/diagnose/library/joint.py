"""Terms acting through a joint reading: the true angle is the encoder reading plus δq (rad).

- ``joint_compliance`` Jj: δq_j = c·τ_j, τ_j the gravity torque about joint j (N·m, `gravity`), c in
  rad/(N·m);
- ``backlash`` Jj: δq_j = −(b/2)·s_j, s_j the sign of joint j's last motion (the load lags the motor), b rad;
  its forms ``Jj (play ≥ X mrad)`` take s_j from the last motion longer than X mrad (a search shorter than the
  play does not turn the link: the approach before it sets the load side);
- ``joint_scale`` Jj: δq_j = ε·q_j (1);
- ``encoder_eccentricity`` Jj: δq_j = a·cos q_j + b·sin q_j (rad);
- ``transmission_error`` Jj: δq_j = a·cos 2q_j + b·sin 2q_j (rad);
- ``wrist_coupling`` Ji->Jj: δq_j = κ·q_i (rad/rad), for the wrist pairs (J4, J5, J6);
- ``joint_coupling`` Ji->Jj: δq_j = κ·q_i (rad/rad) for neighbouring joints J1..J4 (e.g. a J3 driven
  through a parallelogram), and its quadratic form δq_j = κ₂·(q_i − q̄_i)² (rad/rad²), q̄_i the
  campaign's mean angle of joint i (a parallelogram or belt whose transmission is not linear);
- ``coupling_difference`` Ji-Jj on Jj: δq_j = κ·(q_i − q_j) (rad/rad), an error linear in the
  relative angle of two parallel joints (J2, J3);
- ``bump`` (not in any library: an out-of-library test term of the simulator): a Gaussian bump in
  joint j's transmission.

Each constructor takes the arm (`SerialArm`: its joint names) and the joint index(es) and returns
the `term.Effect` with its basis (n, n_joints, k), plausible size and advice.
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.library.gravity import gravity_torque
from pipeline.diagnose.library.term import Effect, one_joint

PLAUSIBLE = {
    "joint_compliance": 1e-4,  # rad/(N·m): 1e4 N·m/rad, a very soft joint
    "backlash": 1e-2,  # rad (0.57°: a worn spur or belt drive, a low-cost servo's gearbox)
    "joint_scale": 5e-3,  # 1
    "encoder_eccentricity": 1e-2,  # rad (a misaligned magnetic encoder's once-per-turn error reaches 0.5–1°)
    "transmission_error": 1e-2,  # rad (the same encoder's twice-per-turn error)
    "wrist_coupling": 1e-2,  # rad/rad
    "joint_coupling": 1e-2,  # rad/rad
    "joint_coupling_quadratic": 1e-2,  # rad/rad²
    "coupling_difference": 1e-2,  # rad/rad
}
ADVICE = {
    "joint_compliance": "add a second payload and reach the same points with the arm stretched and folded",
    "backlash": "approach each pose from both sides of the joint (reverse the joint before the search)",
    "joint_scale": "move the joint over a wider range of its travel",
    "encoder_eccentricity": "spread the poses over a full turn of the joint",
    "transmission_error": "spread the poses over at least half a turn of the joint",
    "wrist_coupling": "vary the driving wrist joint independently of the driven one",
    "joint_coupling": "move the driving joint alone over its range while the driven one stays put",
    "coupling_difference": "vary the two joints' relative angle independently of each one",
}
PLAY_RAD = (1e-3, 2e-3)  # plays (rad) of the backlash forms: a search shorter than the play leaves the link where it was


def play_column(play_rad: float) -> str:
    """The diagnosis table's column of the sign of each joint's last motion longer than `play_rad` (rad)."""
    return f"last_motion_sign_beyond_{play_rad * 1e3:g}mrad"


WRIST_PAIRS = ((3, 4), (3, 5), (4, 5))  # (driving, driven) joint indices of `wrist_coupling`
NEIGHBOURS = ((0, 1), (1, 0), (1, 2), (2, 1), (2, 3), (3, 2))  # (driving, driven) of `joint_coupling`
DIFFERENCE_PAIRS = ((1, 2), (2, 1))  # (other, driven) of `coupling_difference`


# ----- bases (n, n_joints, k) -----------------------------------------------------------------
def _compliance(j):
    def basis(arm, x, t):
        tau = gravity_torque(arm, x, t["joint_positions"], t.get("payload_kg", arm.payload_kg))
        return one_joint(j, arm.n_joints, tau[:, j:j + 1])
    return basis


def _backlash(j):
    def basis(arm, x, t):
        return one_joint(j, arm.n_joints, -0.5 * np.asarray(t["last_motion_sign"], float)[:, j:j + 1])
    return basis


def _backlash_play(j, column):
    def basis(arm, x, t):
        return one_joint(j, arm.n_joints, -0.5 * np.asarray(t[column], float)[:, j:j + 1])
    return basis


def _scale(j):
    def basis(arm, x, t):
        return one_joint(j, arm.n_joints, t["joint_positions"][:, j:j + 1])
    return basis


def _harmonic(j, order):
    def basis(arm, x, t):
        qj = t["joint_positions"][:, j]
        return one_joint(j, arm.n_joints, np.stack([np.cos(order * qj), np.sin(order * qj)], axis=1))
    return basis


def _wrist(src, dst):
    def basis(arm, x, t):
        return one_joint(dst, arm.n_joints, t["joint_positions"][:, src:src + 1])
    return basis


def _bump(j, centre, width):
    def basis(arm, x, t):
        qj = t["joint_positions"][:, j]
        return one_joint(j, arm.n_joints, np.exp(-0.5 * ((qj - centre) / width) ** 2)[:, None])
    return basis


def _coupling(i: int, j: int):
    def basis(arm, x, t):
        return one_joint(j, arm.n_joints, np.asarray(t["joint_positions"], float)[:, i:i + 1])
    return basis


def _quadratic(i: int, j: int):
    def basis(arm, x, t):
        qi = np.asarray(t["joint_positions"], float)[:, i]
        return one_joint(j, arm.n_joints, ((qi - qi.mean()) ** 2)[:, None])
    return basis


def _difference(i: int, j: int):
    def basis(arm, x, t):
        q = np.asarray(t["joint_positions"], float)
        return one_joint(j, arm.n_joints, (q[:, i] - q[:, j])[:, None])
    return basis


# ----- the terms ------------------------------------------------------------------------------
def _names(arm) -> list[str]:
    return [j.name for j in arm.joints]


def compliance(arm, j: int) -> Effect:
    J = _names(arm)[j]
    return Effect("joint_compliance", J, (f"compliance_{J}",), ("rad/(N*m)",), PLAUSIBLE["joint_compliance"],
                  "joint", _compliance(j), 10, f"q_{J}", ADVICE["joint_compliance"])


def backlash(arm, j: int) -> Effect:
    J = _names(arm)[j]
    return Effect("backlash", J, (f"backlash_{J}",), ("rad",), PLAUSIBLE["backlash"], "joint", _backlash(j),
                  20, f"q_{J}", ADVICE["backlash"])


def backlash_play(arm, j: int, play_rad: float, column: str) -> Effect:
    """Backlash whose load side is set by the last motion longer than `play_rad` (table `column`): a gear
    with that much play does not turn its link over a shorter search, the approach before it decides
    (the dead band's hysteresis); a form of `backlash` Jj (`inference.forms` chooses by held-out error)."""
    J = _names(arm)[j]
    return Effect("backlash", f"{J} (play ≥ {play_rad * 1e3:g} mrad)", (f"backlash_{J}",), ("rad",),
                  PLAUSIBLE["backlash"], "joint", _backlash_play(j, column), 21 + int(play_rad * 1e3),
                  f"q_{J}", ADVICE["backlash"], data={"form": {"play_rad": play_rad}})


def scale(arm, j: int) -> Effect:
    J = _names(arm)[j]
    return Effect("joint_scale", J, (f"scale_{J}",), ("1",), PLAUSIBLE["joint_scale"], "joint", _scale(j),
                  30, f"q_{J}", ADVICE["joint_scale"])


def eccentricity(arm, j: int) -> Effect:
    J = _names(arm)[j]
    return Effect("encoder_eccentricity", J, (f"ecc_cos_{J}", f"ecc_sin_{J}"), ("rad", "rad"),
                  PLAUSIBLE["encoder_eccentricity"], "joint", _harmonic(j, 1), 40, f"q_{J}",
                  ADVICE["encoder_eccentricity"])


def transmission_error(arm, j: int) -> Effect:
    J = _names(arm)[j]
    return Effect("transmission_error", J, (f"te2_cos_{J}", f"te2_sin_{J}"), ("rad", "rad"),
                  PLAUSIBLE["transmission_error"], "joint", _harmonic(j, 2), 50, f"q_{J}",
                  ADVICE["transmission_error"])


def wrist_coupling(arm, src: int, dst: int) -> Effect:
    J = _names(arm)
    return Effect("wrist_coupling", f"{J[src]}->{J[dst]}", (f"coupling_{J[src]}_{J[dst]}",), ("rad/rad",),
                  PLAUSIBLE["wrist_coupling"], "joint", _wrist(src, dst), 60, f"q_{J[src]}",
                  ADVICE["wrist_coupling"])


def coupling(arm, i: int, j: int) -> Effect:
    J = _names(arm)
    return Effect("joint_coupling", f"{J[i]}->{J[j]}", (f"coupling_{J[i]}_{J[j]}",), ("rad/rad",),
                  PLAUSIBLE["joint_coupling"], "joint", _coupling(i, j), 62, f"q_{J[i]}", ADVICE["joint_coupling"])


def quadratic_coupling(arm, i: int, j: int) -> Effect:
    J = _names(arm)
    return Effect("joint_coupling", f"{J[i]}->{J[j]} (quadratic)", (f"coupling2_{J[i]}_{J[j]}",),
                  ("rad/rad^2",), PLAUSIBLE["joint_coupling_quadratic"], "joint", _quadratic(i, j), 63,
                  f"q_{J[i]}", ADVICE["joint_coupling"])


def coupling_difference(arm, i: int, j: int) -> Effect:
    J = _names(arm)
    return Effect("coupling_difference", f"{J[i]}-{J[j]} on {J[j]}", (f"diff_{J[i]}_{J[j]}",),
                  ("rad/rad",), PLAUSIBLE["coupling_difference"], "joint", _difference(i, j), 64, f"q_{J[i]}",
                  ADVICE["coupling_difference"])


def bump(arm, joint: int, centre_rad: float, width_rad: float = 0.15) -> Effect:
    """A localised bump in one joint's transmission — deliberately NOT in any library."""
    name = arm.joints[joint].name
    return Effect("bump", f"{name}:{centre_rad:g}", (f"bump_{name}",), ("rad",), 1e-2, "joint",
                  _bump(joint, centre_rad, width_rad), 999, f"q_{name}", "")
