"""A system's measurement model with the gravity terms a run asked for (`--physics`, `--payload`):
shared by `robocal calibrate` and every stage of `robocal run` (ingest records the choice)."""

from __future__ import annotations

from pipeline.errors import RobocalError


def load_with_physics(system, rec, physics: str | None, payload: list[str] | None):
    """`system.load(rec)`, with the gravity terms asked for where the system models them."""
    import inspect

    from pipeline.physics.compliance import parse_payload, parse_spec

    mode, _ = parse_spec(physics)
    loads = payload or []
    if "physics" in inspect.signature(system.load).parameters:
        return system.load(rec, physics=physics, payload=parse_payload(loads))
    if mode == "fixed" or loads:
        raise RobocalError(f"{rec.path}: system {system.SYSTEM} has no gravity terms (--physics, --payload)")
    return system.load(rec)

