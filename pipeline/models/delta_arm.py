"""The Delta robot as a kinematics part: error parameters β and the forward kinematics of a
point fixed to the platform, with its analytic derivatives (seed 003).

`point(β, θ, offset)` is what a measurement type composes with: the position (n, 3) m in the
base frame {A} of the platform point P moved by ``offset`` (m, platform frame), dM/dβ, and the
platform orientation R_P.  The simplified model β' (27 parameters, R_P = I) uses the analytic
forward kinematics; the extended one (36) Newton's solution of the six rod constraints.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.models import delta as dm
from pipeline.models.delta import Delta

VARIANTS = ("simplified", "extended")


@dataclass(frozen=True)
class DeltaKinematics:
    delta: Delta = field(default_factory=Delta)
    variant: str = "simplified"

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise ValueError(f"unknown Delta model variant {self.variant!r} (use one of {VARIANTS})")

    @property
    def extended(self) -> bool:
        return self.variant == "extended"

    @property
    def n_params(self) -> int:
        return 36 if self.extended else 27

    @property
    def n_joints(self) -> int:
        return self.delta.n_legs

    def parameter_names(self) -> list[str]:
        return dm.beta_names(3, self.extended)

    def parameter_units(self) -> list[str]:
        return dm.beta_units(3, self.extended)

    def vector(self) -> np.ndarray:
        return np.zeros(self.n_params)

    def priority(self) -> np.ndarray:
        """Actuator offsets and link lengths (and the extended terms) first, then the base joints
        of legs 2 and 3; leg 1's base joint after them (a translation of {A} equals an
        instrument's translation), the platform joints last (only Δb_i − Δa_i enters)."""
        def level(n: str) -> int:
            leg, key = n.split(".")
            if key.startswith("da_"):
                return 3 if leg == "leg1" else 2
            return 4 if key.startswith("db_") else 1
        return np.array([level(n) for n in self.parameter_names()])

    def simplified_beta(self, beta: np.ndarray) -> np.ndarray:
        """The 27 simplified parameters β' of a β vector of either variant."""
        return dm.split(beta, self.extended)[0].ravel()

    def point(self, beta: np.ndarray, theta: np.ndarray, offset: np.ndarray, jac: bool = False):
        """(M, dM/dβ or None, R_P or None): M = P(β, θ) + R_P·offset (n, 3) m in {A}, R_P (n, 3, 3)
        for the extended model (None: identity) — θ (n, 3) actuator angles, rad."""
        theta = np.atleast_2d(np.asarray(theta, float))
        if self.extended:
            p, R, _ = dm.full_forward(self.delta, beta, theta, extended=True)
            M = p + R @ offset
            if not jac:
                return M, None, R
            Jb, _ = dm.full_jacobian(self.delta, beta, theta, p, R, offset, extended=True)
            return M, Jb, R
        b = self.simplified_beta(beta)
        p, _ = dm.forward(self.delta, b, theta)
        M = p + offset
        return M, (dm.forward_jacobian(self.delta, b, theta, p) if jac else None), None
