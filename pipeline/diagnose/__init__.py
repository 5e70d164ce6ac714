"""Diagnosis: find the physics the geometric model left out, name it, model it, show the held-out
fit improve (docs/guide/diagnose.md).

The method (`method.diagnose`, a pure function of a measurement model and a diagnosis table):
fit the geometry; build every candidate term's signature at the solution; gate the candidates the
campaign cannot see; select the ones the data ask for (grouped F, Holm); refit geometry and terms
jointly; confirm out of sample; locate what is left; grade each name; write the document.

Sub-packages, in the order a reader meets them:

- `library`: the physics terms (one module per family), pure numpy functions of (parameters, data)
  with their Jacobians, importable without the rest of the diagnosis;
- `inference`: projection, gate, stepwise selection, pose-clustered inference, forms, joint refit;
- `verdict`: the held-out arbiter, lack of fit, influence of single records, confidence and status;
- `adapters`: what is system-specific (arc-welder touch, Delta + laser tracker, SCORBOT scanner,
  URDF robot);
- `document`: the content of DIR/diagnosis.json and its plots as arrays.

`stage` is the `diagnose` stage of `robocal run` (files).  The names below are this package's public
door; they are imported on first use, so that `pipeline.diagnose.library` stays light.
"""

from __future__ import annotations

import importlib

__all__ = ["Adapter", "Effect", "Settings", "diagnose", "diagnose_recording", "touch_library"]

_WHERE = {
    "Adapter": "pipeline.diagnose.adapters.adapter",
    "Effect": "pipeline.diagnose.library.term",
    "Settings": "pipeline.diagnose.method",
    "diagnose": "pipeline.diagnose.method",
    "diagnose_recording": "pipeline.diagnose.stage",
    "touch_library": "pipeline.diagnose.library.touch",
}


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(importlib.import_module(_WHERE[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
