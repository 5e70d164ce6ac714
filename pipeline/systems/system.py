"""A reference system as a composition of generic parts, each named by its role.

A `System` declares, in one place, which module (or ``module:attribute``) plays each role for
one system: the recording loader and the measurement model it builds, the kinematic chain, the
instrument and fixture, the physics terms a diagnosis tests (its adapter), the simulator, the
visualizer, the pose planner and the compensator.  Parts are dotted import paths, resolved only
when asked for (`part`), so declaring a system imports none of them.  A role the system does
not have is None.
"""

from __future__ import annotations

import importlib
import importlib.util
from dataclasses import dataclass, fields
from typing import Any

ROLES = ("loader", "model", "measurement", "kinematics", "instrument", "fixture", "physics", "simulator", "visualizer",
         "planner", "compensator")


@dataclass(frozen=True)
class System:
    """One system's parts by role (dotted paths: ``package.module`` or ``package.module:attribute``).

    loader: module with ``SYSTEM``, ``MEASUREMENT_CHANNEL`` and ``load(rec) -> (model, table)``;
    model: the system's measurement model (what `load` builds: measurement type over kinematics);
    measurement: the generic measurement type; kinematics: the kinematic chain/model class;
    instrument: what measures (sensor model), fixture: what is measured against (jig);
    physics: the diagnosis adapter (the system's physics terms and error model);
    simulator: the campaign simulator module; visualizer: module with ``log_system`` (rerun);
    planner: module with ``candidates(n, seed)`` (pose planning; a URDF robot's
    ``candidates_for(model, n, seed)``); compensator: module with
    ``compensate`` (inverse kinematics of a program of targets)."""

    name: str
    measurement_channel: str
    loader: str
    model: str
    measurement: str
    kinematics: str
    instrument: str | None = None
    fixture: str | None = None
    physics: str | None = None
    simulator: str | None = None
    visualizer: str | None = None
    planner: str | None = None
    compensator: str | None = None

    def path(self, role: str) -> str | None:
        """The dotted path declared for `role` (None: the system has no such part)."""
        if role not in ROLES:
            raise KeyError(f"{role!r} is not a role of a system (roles: {', '.join(ROLES)})")
        return getattr(self, role)

    def part(self, role: str) -> Any:
        """The part playing `role`, imported now: a module, or the module's attribute after ``:``.
        None when the system has no such part."""
        path = self.path(role)
        if path is None:
            return None
        module, _, attr = path.partition(":")
        mod = importlib.import_module(module)
        return getattr(mod, attr) if attr else mod

    def parts(self) -> dict[str, str]:
        """Every declared role → its dotted path (roles the system has)."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if f.name in ROLES and getattr(self, f.name) is not None}


def module_exists(path: str) -> bool:
    """The module of dotted `path` can be imported (found without importing it)."""
    try:
        return importlib.util.find_spec(path.partition(":")[0]) is not None
    except ModuleNotFoundError:
        return False
