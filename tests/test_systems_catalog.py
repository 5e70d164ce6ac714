"""Each reference system is declared once (`pipeline.systems.catalog`) as generic parts by role;
every declared part exists and offers what its role promises, and declaring imports none of them."""

from __future__ import annotations

import importlib
import pkgutil
import subprocess
import sys

import pytest

import pipeline.systems as systems_pkg
from pipeline.errors import RobocalError
from pipeline.systems.catalog import CATALOG
from pipeline.systems.registry import SYSTEMS, declaration
from pipeline.systems.system import ROLES, System

# What each role's part must offer (an attribute of the module, or the part itself is callable).
# Each entry: a name the part must have, or a tuple of names one of which it must have.
OFFERS = {"loader": ("SYSTEM", "MEASUREMENT_CHANNEL", "load"), "visualizer": ("log_system",),
          "planner": (("candidates", "candidates_for"),), "compensator": ("compensate",)}


@pytest.mark.parametrize("name", sorted(CATALOG))
def test_every_declared_part_resolves_and_offers_its_role(name):
    s = CATALOG[name]
    assert s.name == name
    loader = s.part("loader")
    assert (loader.SYSTEM, loader.MEASUREMENT_CHANNEL) == (s.name, s.measurement_channel)
    assert SYSTEMS[name] is loader
    for role, path in s.parts().items():
        part = s.part(role)
        assert part is not None, (name, role, path)
        for attr in OFFERS.get(role, ()):
            names = attr if isinstance(attr, tuple) else (attr,)
            assert any(hasattr(part, a) for a in names), f"{name}: {role} {path} has none of {names}"
        if role in ("model", "measurement", "kinematics", "instrument", "physics"):
            assert callable(part), (name, role, path)
    assert s.model.partition(":")[0] == s.loader  # the loader builds the declared model


def test_the_model_is_the_measurement_type_over_the_kinematics():
    for name in ("arc-welder", "delta-tracker", "scorbot-scanner"):
        s = CATALOG[name]
        assert issubclass(s.part("model"), s.part("measurement")), name


def test_every_system_module_is_declared():
    """A module of pipeline.systems that defines SYSTEM (a loader) has a declaration."""
    loaders = set()
    for m in pkgutil.iter_modules(systems_pkg.__path__):
        mod = importlib.import_module(f"pipeline.systems.{m.name}")
        if hasattr(mod, "SYSTEM"):
            loaders.add(mod.__name__)
    assert loaders == {s.loader for s in CATALOG.values()}


def test_declaring_imports_no_part():
    code = ("import sys, pipeline.systems.catalog as c\n"
            "print(sorted(m for m in sys.modules if m.startswith(('pipeline.diagnose', 'pipeline.simulate', "
            "'pipeline.visualize', 'pipeline.plan', 'pipeline.compensate', 'pipeline.models', "
            "'pipeline.systems.arc_welder'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_roles_and_unknown_names_are_clear_errors():
    s = CATALOG["urdf"]
    assert s.path("visualizer") is None and s.part("visualizer") is None
    with pytest.raises(KeyError, match="not a role"):
        s.path("camera")
    with pytest.raises(RobocalError, match=r"unknown system 'nope' \(known: arc-welder, delta-tracker"):
        declaration("nope")
    assert set(ROLES) < {f for f in System.__dataclass_fields__}
