"""One robot, several sessions, each measured in its own instrument frame (per-recording registration).

Wraps any measurement model whose instrument frame is ``base.x … base.yaw``: the first session keeps
``base.*``, session s ≥ 1 gets ``base.<k>@<s>`` (appended after the model's own parameters, in the
registration group).  Rows carry their session in the data column ``session``; each session's rows
are evaluated with its frame (a loop over sessions, vectorised inside).  Everything else (the robot,
tool, targets) is shared.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.identify.model import Table, take

FRAME = ("x", "y", "z", "roll", "pitch", "yaw")


@dataclass(frozen=True)
class SessionFrames:
    inner: object
    n_sessions: int

    def __getattr__(self, name):  # everything not overridden is the inner model's
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)

    @property
    def _base(self) -> list[int]:
        names = self.inner.parameter_names()
        return [names.index(f"base.{k}") for k in FRAME]

    @property
    def _p(self) -> int:
        return len(self.inner.parameter_names())

    def without(self, names) -> SessionFrames:
        """The same sessions around the inner model without the terms of `names` it can drop (its
        ``without``; held at 0 they are no-ops: `pipeline.identify.least_squares.fit`)."""
        hook = getattr(self.inner, "without", None)
        small = hook(names) if hook is not None else self.inner
        return self if small is self.inner else SessionFrames(small, self.n_sessions)

    def session_names(self) -> list[str]:
        return [f"base.{k}@{s}" for s in range(1, self.n_sessions) for k in FRAME]

    def parameter_names(self) -> list[str]:
        return self.inner.parameter_names() + self.session_names()

    def parameter_units(self) -> list[str]:
        u = self.inner.parameter_units()
        return u + [u[i] for _ in range(1, self.n_sessions) for i in self._base]

    def nominal(self) -> np.ndarray:
        x = np.asarray(self.inner.nominal(), float)
        return np.r_[x, np.tile(x[self._base], self.n_sessions - 1)]

    def priority(self) -> np.ndarray:
        pr = np.asarray(self.inner.priority())
        return np.r_[pr, np.tile(pr[self._base], self.n_sessions - 1)]

    def groups(self) -> dict[str, list[str]]:
        g = dict(self.inner.groups())
        g["registration"] = list(g.get("registration", [])) + self.session_names()
        return g

    def session_x(self, x: np.ndarray, s: int) -> np.ndarray:
        """The inner model's parameter vector of session `s`."""
        x = np.asarray(x, float)
        xs = x[:self._p].copy()
        if s > 0:
            xs[self._base] = x[self._p + 6 * (s - 1):self._p + 6 * s]
        return xs

    def _sessions(self, data: Table):
        ses = np.asarray(data.get("session", np.zeros(len(data["joint_positions"]), int)), int)
        return [(s, np.flatnonzero(ses == s)) for s in range(self.n_sessions) if np.any(ses == s)]

    def residuals(self, x: np.ndarray, data: Table) -> np.ndarray:
        out = np.zeros((len(data["joint_positions"]), self.inner.residual_dim))
        for s, rows in self._sessions(data):
            out[rows] = np.asarray(self.inner.residuals(self.session_x(x, s), take(data, rows)), float).reshape(
                len(rows), -1)
        return out

    def _spread(self, J_s: np.ndarray, s: int) -> np.ndarray:
        J = np.zeros(J_s.shape[:-1] + (len(self.parameter_names()),))
        J[..., :self._p] = J_s
        if s > 0:
            cols = slice(self._p + 6 * (s - 1), self._p + 6 * s)
            J[..., cols] = J_s[..., self._base]
            J[..., self._base] = 0.0
        return J

    def jacobian(self, x: np.ndarray, data: Table) -> np.ndarray:
        out = np.zeros((len(data["joint_positions"]), self.inner.residual_dim, len(self.parameter_names())))
        for s, rows in self._sessions(data):
            J_s = np.asarray(self.inner.jacobian(self.session_x(x, s), take(data, rows)), float)
            out[rows] = self._spread(J_s.reshape(len(rows), self.inner.residual_dim, -1), s)
        return out

    def points(self, x: np.ndarray, data: Table):
        n = len(data["joint_positions"])
        p, J = np.zeros((n, 3)), np.zeros((n, 3, len(self.parameter_names())))
        for s, rows in self._sessions(data):
            ps, Js = self.inner.points(self.session_x(x, s), take(data, rows))
            p[rows], J[rows] = ps, self._spread(Js, s)
        return p, J

    def initial_guess(self, data: Table) -> np.ndarray:
        x = self.nominal()
        for s, rows in self._sessions(data):
            xs = np.asarray(self.inner.initial_guess(take(data, rows)), float)
            if s == 0:
                x[:self._p] = xs
            else:
                x[self._p + 6 * (s - 1):self._p + 6 * s] = xs[self._base]
        return x

    def uncalibrated(self, data: Table) -> np.ndarray:
        from pipeline.identify.complexity import fixed_for
        from pipeline.identify.least_squares import FitOptions, fit

        return fit(self, data, FitOptions(fixed=fixed_for(self, ["registration"]), before=False)).x

    def exports(self, x: np.ndarray) -> dict[str, str]:
        return self.inner.exports(np.asarray(x, float)[:self._p])

    def describe(self, x: np.ndarray) -> dict:
        d = self.inner.describe(np.asarray(x, float)[:self._p])
        d["session_frames"] = {n: float(v) for n, v in zip(self.session_names(), np.asarray(x, float)[self._p:])}
        return d
