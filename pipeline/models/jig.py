"""Touch-sensing jig: a stepped aluminium block whose faces fix one jig-frame coordinate each."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

AXIS_INDEX = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True)
class Face:
    """Plane `axis = coordinate` (m); `normal_sign` points out of the material;
    `extent` bounds the face in the two other axes (in x,y,z order), m."""

    id: str
    axis: str
    coordinate: float
    normal_sign: int
    extent: tuple[tuple[float, float], tuple[float, float]]

    @property
    def axis_index(self) -> int:
        return AXIS_INDEX[self.axis]

    @property
    def normal(self) -> np.ndarray:
        n = np.zeros(3)
        n[self.axis_index] = self.normal_sign
        return n

    def other_axes(self) -> tuple[int, int]:
        a = [i for i in range(3) if i != self.axis_index]
        return a[0], a[1]


@dataclass(frozen=True)
class Jig:
    name: str
    faces: tuple[Face, ...]
    tolerance_m: float = 2e-5
    material: str = "aluminium 6061-T6"

    def face(self, face_id: str) -> Face:
        for f in self.faces:
            if f.id == face_id:
                return f
        raise KeyError(face_id)

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": "touch_jig", "name": self.name, "material": self.material, "tolerance_m": self.tolerance_m,
            "faces": [{"id": f.id, "axis": f.axis, "coordinate": f.coordinate, "normal_sign": f.normal_sign,
                       "extent": [list(f.extent[0]), list(f.extent[1])]} for f in self.faces],
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Jig":
        faces = tuple(Face(f["id"], f["axis"], float(f["coordinate"]), int(f["normal_sign"]),
                           (tuple(f["extent"][0]), tuple(f["extent"][1]))) for f in d["faces"])
        return cls(name=d["name"], faces=faces, tolerance_m=float(d.get("tolerance_m", 2e-5)),
                   material=d.get("material", ""))


def stepped_block() -> Jig:
    """The reference jig: a 300 × 200 mm block with three steps (60, 100, 140 mm high).

    Faces in all three orientations: three step tops (z), the two risers and both ends (x),
    front and back (y).  Coordinates in the jig frame W, whose origin is the block's corner.
    """
    F = Face
    faces = (
        F("top1", "z", 0.060, +1, ((0.005, 0.095), (0.010, 0.190))),
        F("top2", "z", 0.100, +1, ((0.105, 0.195), (0.010, 0.190))),
        F("top3", "z", 0.140, +1, ((0.205, 0.295), (0.010, 0.190))),
        F("riser12", "x", 0.100, -1, ((0.010, 0.190), (0.065, 0.095))),
        F("riser23", "x", 0.200, -1, ((0.010, 0.190), (0.105, 0.135))),
        F("end_low", "x", 0.000, -1, ((0.010, 0.190), (0.010, 0.055))),
        F("end_high", "x", 0.300, +1, ((0.010, 0.190), (0.010, 0.135))),
        F("front", "y", 0.200, +1, ((0.010, 0.290), (0.010, 0.055))),
        F("back", "y", 0.000, -1, ((0.010, 0.290), (0.010, 0.055))),
    )
    return Jig(name="stepped-block-300x200", faces=faces)
