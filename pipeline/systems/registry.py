"""Which system a recording belongs to, and the module that models it.

A system module offers ``SYSTEM`` (its name), ``MEASUREMENT_CHANNEL`` and
``load(rec) -> (MeasurementModel, table)``.
"""

from __future__ import annotations

from types import ModuleType

from pipeline.errors import RobocalError
from pipeline.recording.reader import Recording
from pipeline.recording.schemas import META_CAMPAIGN
import importlib
import pkgutil

import pipeline.systems as _pkg


def _discover() -> dict[str, ModuleType]:
    """Every module of `pipeline.systems` that defines SYSTEM is a system."""
    found: dict[str, ModuleType] = {}
    for m in sorted(pkgutil.iter_modules(_pkg.__path__), key=lambda m: m.name):
        mod = importlib.import_module(f"pipeline.systems.{m.name}")
        if hasattr(mod, "SYSTEM") and hasattr(mod, "load"):
            found[mod.SYSTEM] = mod
    return found


SYSTEMS: dict[str, ModuleType] = _discover()


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
