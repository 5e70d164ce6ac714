"""Which model choice a fit takes: ``--model-choice auto|groups|shrinkage`` resolved for one recording.

``groups`` keeps the parameter groups that lower the k-fold held-out error (`pipeline.identify.complexity`);
``shrinkage`` estimates every parameter pulled toward nominal by its prior, the scale chosen by leaving out
whole sessions / placements / sockets, else by the evidence (`pipeline.identify.evidence`).  ``auto`` (the
default) decides from the data and the model only, never from where the recording came from (imported,
simulated): ``shrinkage`` for a single-chain URDF robot — one tip and no coupled joints, whose residuals are lengths (not a
camera's pixels) — where it predicted whole held-out sessions and placements of real robots (TIAGo's arm,
Panda) better than ``groups`` and at a fraction of the cost; and ``groups`` otherwise: the seed papers'
reference systems (arc welder, scanner, Delta), whose figures rest on it, trees (several tips, coupled joints:
no real data has judged shrinkage there) and cameras.
"""

from __future__ import annotations

CHOICES = ("auto", "groups", "shrinkage")


def check(choice: str) -> str:
    """`choice` if known; else a one-line error naming the known ones."""
    if choice not in CHOICES:
        from pipeline.errors import RobocalError

        raise RobocalError(f"--model-choice {choice!r}: expected {', '.join(CHOICES)}")
    return choice


def resolve(choice: str, system: str, model, tree: bool = False) -> dict:
    """{asked, route: groups|shrinkage, reason} of `choice` for a recording of `system` (its name), its
    measurement `model` and whether it is a tree (`urdf_robot.is_tree`); the campaign's provenance (imported,
    simulated) is deliberately not an input."""
    check(choice)
    if choice != "auto":
        return {"asked": choice, "route": choice, "reason": f"--model-choice {choice}"}
    if system != "urdf":
        why = f"auto: system {system} (a seed reference system) keeps the group selection"
        return {"asked": "auto", "route": "groups", "reason": why}
    if getattr(model, "residual_unit", "m") != "m":
        return {"asked": "auto", "route": "groups", "reason": "auto: camera residuals (px) keep the group selection"}
    if tree:
        return {"asked": "auto", "route": "groups",
                "reason": "auto: a tree (several tips or coupled joints) keeps the group selection"}
    return {"asked": "auto", "route": "shrinkage",
            "reason": "auto: a single-chain URDF robot (lengths measured) takes shrinkage toward nominal"}
