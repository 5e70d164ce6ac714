"""The independent generator's own touch jig: plane faces of a machined block, from its drawing.

Shares no code with robocal (`pipeline.models.jig` describes the same block for the product; the generator
draws it here from the block's dimensions).  A face is the plane x_axis = coordinate (m, jig frame: origin at
the block's corner, z up), its outward normal along ±axis, and the rectangle a probe may touch on it (the two
other axes, in x, y, z order, m)."""

from __future__ import annotations

from dataclasses import dataclass

AXES = "xyz"


@dataclass(frozen=True)
class Face:
    id: str
    axis: str  # "x" | "y" | "z"
    coordinate: float  # m
    normal_sign: int  # +1: the material lies below the coordinate
    extent: tuple  # ((lo, hi), (lo, hi)) m along the two other axes

    @property
    def axis_index(self) -> int:
        return AXES.index(self.axis)

    def other_axes(self) -> tuple[int, int]:
        a, b = (i for i in range(3) if i != self.axis_index)
        return a, b


@dataclass(frozen=True)
class Block:
    name: str
    faces: tuple


def stepped_block(length: float = 0.3, depth: float = 0.2, heights=(0.06, 0.10, 0.14), edge: float = 0.01,
                  step_edge: float = 0.005) -> Block:
    """A block `length` (x) × `depth` (y) m of len(heights) steps rising along x, each step length/len(heights)
    long: its step tops (z), the risers between steps and both ends (x), front and back (y).  A probe keeps
    `edge` off the block's outer edges and `step_edge` off an edge where two steps meet (and off a step top's
    ends along x).  Numbers rounded to the µm (the drawing's)."""
    r = lambda v: round(v, 6)  # noqa: E731
    k = len(heights)
    w = length / k
    y_in = (r(edge), r(depth - edge))
    faces = [Face(f"top{i + 1}", "z", r(h), +1, ((r(i * w + step_edge), r((i + 1) * w - step_edge)), y_in))
             for i, h in enumerate(heights)]
    faces += [Face(f"riser{i + 1}{i + 2}", "x", r((i + 1) * w), -1,
                   (y_in, (r(heights[i] + step_edge), r(heights[i + 1] - step_edge)))) for i in range(k - 1)]
    faces += [Face("end_low", "x", 0.0, -1, (y_in, (r(edge), r(heights[0] - step_edge)))),
              Face("end_high", "x", r(length), +1, (y_in, (r(edge), r(heights[-1] - step_edge))))]
    low_sides = ((r(edge), r(length - edge)), (r(edge), r(heights[0] - step_edge)))
    faces += [Face("front", "y", r(depth), +1, low_sides), Face("back", "y", 0.0, -1, low_sides)]
    return Block(f"stepped-block-{length * 1e3:.0f}x{depth * 1e3:.0f}", tuple(faces))


def shifted_copy(block: Block, dx: float, dz: float, prefix: str = "s_") -> Block:
    """`block` and a copy of it moved by `dx` along x and `dz` along z (m), the copy's faces named `prefix` + id."""
    off = (dx, 0.0, dz)
    faces = []
    for f in block.faces:
        a, b = f.other_axes()
        faces.append(Face(prefix + f.id, f.axis, f.coordinate + off[f.axis_index], f.normal_sign,
                          ((f.extent[0][0] + off[a], f.extent[0][1] + off[a]),
                           (f.extent[1][0] + off[b], f.extent[1][1] + off[b]))))
    return Block(f"{block.name}+station({dx:g},{dz:g})", block.faces + tuple(faces))
