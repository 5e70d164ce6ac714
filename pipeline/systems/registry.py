"""Which system a recording belongs to, and the module that models it.

The systems are those declared in `pipeline.systems.catalog`; each one's loader module offers
``SYSTEM`` (its name), ``MEASUREMENT_CHANNEL`` and ``load(rec) -> (MeasurementModel, table)``.
"""

from __future__ import annotations

from types import ModuleType

from pipeline.errors import RobocalError
from pipeline.recording.reader import Recording
from pipeline.recording.schemas import META_CAMPAIGN
from pipeline.systems.catalog import CATALOG
from pipeline.systems.system import System

SYSTEMS: dict[str, ModuleType] = {name: s.part("loader") for name, s in CATALOG.items()}


def declaration(name: str) -> System:
    """The declaration of system `name`; an unknown name is a one-line error listing the known ones."""
    if name not in CATALOG:
        raise RobocalError(f"unknown system {name!r} (known: {', '.join(sorted(CATALOG))})")
    return CATALOG[name]


def detect(rec: Recording) -> ModuleType:
    """The system named in the campaign metadata, else the one whose channel is present.
    The metadata is checked first (`ingest.guards.check_metadata`): a model is never built from
    non-finite or absurd numbers."""
    from pipeline.ingest.guards import check_metadata

    check_metadata(rec)
    name = rec.metadata.get(META_CAMPAIGN, {}).get("system")
    if name in SYSTEMS:
        return SYSTEMS[name]
    for mod in SYSTEMS.values():
        if rec.messages.raw.get(mod.MEASUREMENT_CHANNEL):
            return mod
    have = ", ".join(sorted(t for t, m in rec.messages.raw.items() if m)) or "none"
    want = ", ".join(sorted(m.MEASUREMENT_CHANNEL for m in SYSTEMS.values()))
    raise RobocalError(f"{rec.path}: no measurement channel found (looked for {want}; present: {have})")


def load_with_physics(system, rec, physics: str | None, payload: list[str] | None):
    """`system.load(rec)`, with the gravity terms asked for where the system models them."""
    import inspect

    from pipeline.physics.compliance import parse_payload, parse_spec

    mode, _ = parse_spec(physics)
    loads = payload or []
    if "physics" in inspect.signature(system.load).parameters:
        return system.load(rec, physics=physics or "auto", payload=parse_payload(loads))
    if mode == "fixed" or loads:
        raise RobocalError(f"{rec.path}: system {system.SYSTEM} has no gravity terms (--physics, --payload)")
    return system.load(rec)
