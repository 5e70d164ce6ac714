"""A physics term of the library (`Effect`) and what every term shares: its signature in a
measurement model's residual, its value, and the look-up of a term by name.

A term is a named, located model with a few physical parameters θ.  Its *basis*
``B = basis(arm, x, table)`` is a pure numpy function of (geometric parameters x, data table); the
term's value is B·θ, so B is also its Jacobian with respect to θ.  Terms act in one of three places:

- ``joint``: the true joint angle is the encoder reading plus δq = B·θ, B (n, n_joints, k) rad per
  unit (compliance, backlash, scale, harmonics, couplings);
- ``tip``: the true tip is displaced by D·θ in the jig frame {W}, D = B (n, 3, k) m per unit
  (thermal drift and growth, trigger pretravel and latency, face shape, wire stick-out);
- ``coordinate``: the true face coordinate differs from the drawing by B·θ, B (n, k) m per unit
  (face offset).

Its *signature* ``S(x, table)`` (n, k) (`signature`) is the change of the measurement model's
residual (model − measured, m) per unit of θ at x — a Jacobian column block the identification can
append.  Sign conventions are shared with `pipeline.simulate.effects`, which injects the same
physics into the *true* robot.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from pipeline.models import serial_arm
from pipeline.models.serial_arm import SerialArm

Table = Mapping[str, np.ndarray]


@dataclass(frozen=True)
class Effect:
    """One candidate term at one location (see module docstring).

    `plausible` is the largest physically plausible |θ| (units of `units`); `tolerance` is
    a size below which the term is immaterial (e.g. the jig's machining tolerance), used as
    an interval null hypothesis; `confounders` names the look-alikes, terms whose union may absorb
    this one.  `variable` names what its signature is a function of, so lack-of-fit structure can be
    matched to findings.  Lower `priority` wins ties.
    """

    name: str
    location: str
    parameters: tuple[str, ...]
    units: tuple[str, ...]
    plausible: float
    where: str  # "joint" | "tip" | "coordinate"
    basis: Callable[[SerialArm, np.ndarray, Table], np.ndarray]
    priority: int
    variable: str
    advice: str
    tolerance: float = 0.0
    confounders: tuple[str, ...] = ()  # look-alikes: term names whose union may absorb this one
    data: dict = field(default_factory=dict, compare=False)

    @property
    def label(self) -> str:
        return f"{self.name}@{self.location}"

    @property
    def k(self) -> int:
        return len(self.parameters)

    @property
    def family(self) -> tuple[str, str, str]:
        """(name, place, variable) shared by the forms of one term (`inference.forms`): the location up to
        a form in brackets, e.g. joint_coupling J2->J3 and J2->J3 (quadratic)."""
        return self.name, str(self.location).split(" (")[0], self.variable

    def value(self, arm: SerialArm, x: np.ndarray, table: Table, theta: np.ndarray) -> np.ndarray:
        """The term's value B·θ: δq (n, n_joints) rad (``joint``), the tip displacement (n, 3) m in {W}
        (``tip``) or the face coordinate change (n,) m (``coordinate``)."""
        return self.jacobian(arm, x, table) @ np.atleast_1d(np.asarray(theta, float))

    def jacobian(self, arm: SerialArm, x: np.ndarray, table: Table) -> np.ndarray:
        """∂value/∂θ: the basis B (the term is linear in θ)."""
        return self.basis(arm, x, table)


def axis_rows(table: Table) -> tuple[np.ndarray, np.ndarray]:
    """(row index, measured jig axis 0/1/2) of each touch measurement."""
    ax = np.asarray(table["axis"], int)
    return np.arange(ax.size), ax


def one_joint(j: int, nj: int, cols: np.ndarray) -> np.ndarray:
    """Basis (n, nj, k) acting on joint j only, with columns `cols` (n, k)."""
    out = np.zeros((cols.shape[0], nj, cols.shape[1]))
    out[:, j, :] = cols
    return out


def along_axis(t: Table, cols: np.ndarray) -> np.ndarray:
    """(n, 3, k) tip basis with the columns `cols` (n, k) on each row's measured jig axis."""
    ax = np.asarray(t["axis"], int)
    D = np.zeros((ax.size, 3, cols.shape[1]))
    D[np.arange(ax.size), ax, :] = cols
    return D


def signature(effect: Effect, arm: SerialArm, x: np.ndarray, table: Table, Jq: np.ndarray | None = None) -> np.ndarray:
    """Residual change per unit parameter, (n, k) m/unit, at geometric parameters x.
    `Jq` (n, 3, n_joints): the joint Jacobian at x, when the caller has it already."""
    rows, ax = axis_rows(table)
    B = effect.basis(arm, x, table)
    if effect.where == "joint":
        if Jq is None:
            _, Jq = serial_arm.joint_jacobian(x, table["joint_positions"])
        return np.einsum("nj,njk->nk", Jq[rows, ax], B)
    if effect.where == "tip":
        return B[rows, ax]
    return B  # coordinate: already (n, k)


def joint_offsets(effects_and_values, arm: SerialArm, x: np.ndarray, table: Table) -> np.ndarray:
    """Total δq (n, n_joints) rad of joint terms with values θ (simulator and re-simulation)."""
    n = np.asarray(table["joint_positions"]).shape[0]
    dq = np.zeros((n, arm.n_joints))
    for e, theta in effects_and_values:
        if e.where == "joint":
            dq += np.einsum("njk,k->nj", e.basis(arm, x, table), np.atleast_1d(np.asarray(theta, float)))
    return dq


def pick(lib: list[Effect], name: str, location: str | None) -> Effect:
    """The entry `name@location` of a term library (location may be omitted when unique);
    ValueError listing the options otherwise."""
    hits = [e for e in lib if e.name == name and (location is None or e.location == location)]
    if len(hits) != 1:
        options = sorted({e.label for e in lib if e.name == name}) or sorted({e.name for e in lib})
        raise ValueError(f"effect {name}@{location}: expected one match, options: {', '.join(options)}")
    return hits[0]
