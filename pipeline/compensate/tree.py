"""`Kinematics` (`pipeline.compensate.ik`) of one tip of a URDF robot's tree, with its physics.

The inverse kinematics solves for the joint *readings* (`UrdfTree.joint_names`, the coupled joints
driven by them): the pose of tip `k` at readings q is the forward kinematics of the deflected
configuration — q expanded by the couplings, plus each compliant joint's turn c·τ(q) and each
lateral tilt c⊥·τ⊥(q) (`TreePointModel.deflected`), τ the gravity load of the whole tree and of
`payload` at q (Pinocchio).  A controller that commands these readings lands the tip on target
under the robot's own gravity and the payload, to first order in the deflection (the loads are taken
at the readings, as in the calibration).  The joint Jacobian is the rigid one through the coupling
matrix (the derivative of the deflection, c·∂τ/∂q ≈ 1e-3, only slows the Newton steps slightly);
the solver's error is that of the exact deflected pose.  With `physics=False` the physics parameters
are held at 0 (the rigid calibrated robot).  A calibrated backlash b (``J.backlash``) shifts joint J by
b·d/2 with d = `approach` (+1: every joint of the program reaches its target moving towards higher
values, −1: lower, 0 (default): unknown, the middle of the play).  Poses in the instrument (work)
frame, m and rad.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from pipeline.models import chain as ch


@dataclass(frozen=True, eq=False)
class TreeKinematics:
    """Tip `tip` of a `TreePointModel`'s tree (see module docstring)."""

    model: object
    tip: int = 0
    physics: bool = True
    approach: int = 0  # direction of approach of every joint (−1/0/+1) for the backlash terms
    n_joints: int = field(init=False)
    lower: np.ndarray = field(init=False)
    upper: np.ndarray = field(init=False)

    def __post_init__(self):
        kin = self.model.kin
        object.__setattr__(self, "n_joints", int(kin.n_joints))
        object.__setattr__(self, "lower", np.asarray(kin.lower, float))
        object.__setattr__(self, "upper", np.asarray(kin.upper, float))

    @classmethod
    def of(cls, model, payload: tuple = (), tip: str | None = None, physics: bool = True,
           approach: int = 0) -> "TreeKinematics":
        """From a `TreePointModel`; `payload` replaces the model's (the load the program carries);
        `tip` a link name of the tree's tips (default the first)."""
        from pipeline.errors import RobocalError

        tips = list(model.kin.tips)
        if tip is not None and tip not in tips:
            raise RobocalError(f"--tip {tip!r}: not a tip of the calibrated tree ({', '.join(tips)})")
        return cls(replace(model, payload=tuple(payload)), tips.index(tip) if tip else 0, physics, int(approach))

    def _data(self, q: np.ndarray) -> dict:
        data = {"joint_positions": q, "target": np.full(len(q), self.tip, np.int64)}
        if self.approach:
            data["approach"] = np.full(q.shape, self.approach, np.int8)
        return data

    def _x(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float)
        if not self.physics:
            x = x.copy()
            x[self.model.n_kin:] = 0.0
        return x

    def _full(self, x: np.ndarray, q: np.ndarray) -> np.ndarray:
        q = np.atleast_2d(np.asarray(q, float))
        x = self._x(x)
        if not np.any(x[self.model.n_kin:]):
            return self.model.kin.expand(q)
        return self.model.deflected(x, self._data(q))

    def pose(self, x, q):
        c = self.model.kin.chain(self.tip)
        return ch.forward(c, self._x(x)[: self.model.n_kin], self._full(x, q))

    def pose_jacobian(self, x, q):
        c = self.model.kin.chain(self.tip)
        xk = self._x(x)[: self.model.n_kin]
        full = self._full(x, q)
        R, p, *_ = ch.walk(c, xk, full, True)
        _, Jp, Jw = ch.joint_jacobian(c, xk, full, angular=True)
        A = self.model.kin.coupling_matrix()  # d q_full / d q_read (the lateral columns do not follow q)
        nj = A.shape[0]
        J = np.concatenate([Jp[:, :, :nj], Jw[:, :, :nj]], axis=1) @ A
        return R.copy(), p.copy(), J

    def point_jacobian(self, x, q) -> np.ndarray:
        """d tool point / d parameters (N, 3, P) over every parameter of the model (physics included)."""
        q = np.atleast_2d(np.asarray(q, float))
        return self.model.points(self._x(x), self._data(q))[1]


def is_tree_model(model) -> bool:
    """Whether `model` is a `TreePointModel` (points on the tips of a `UrdfTree`)."""
    return hasattr(getattr(model, "kin", None), "all_joints") and hasattr(model, "deflected")
