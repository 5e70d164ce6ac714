"""The robot of a recording as ROS publishes it: ``robot_state_publisher``'s split of the URDF's transforms
into the static ones (``/tf_static``: every fixed joint of the URDF, plus robocal's two frames) and the
moving ones (``/tf``: the calibrated chain's movable joints at each posture), pure numpy.

One tree: every frame has one parent — the URDF's own joints, the root link → ``robocal_instrument``
(the instrument hangs below the root, as in model.urdf: the inverse of the nominal instrument → root
registration, the identity for a URDF robot) and each tip link → ``robocal_tool`` (``robocal_tool_<tip>``
for a tree measured on several tips).  Translations m; rotations 3×3.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from pipeline.models.urdf import matrix_of_rpy
from pipeline.recording.scene import TOOL_FRAME, chain_transforms


@dataclass(frozen=True)
class RobotFrames:
    """What a bag needs of the robot: its URDF text, the joints read (names, in the recording's order),
    the static transforms (parent, child, 4×4) and `moving(q)` → (pairs, (N, K, 4, 4)) at postures q."""

    urdf: str
    joint_names: list[str]
    static: list[tuple[str, str, np.ndarray]]
    kin: object

    def moving(self, q: np.ndarray) -> tuple[list[tuple[str, str]], np.ndarray]:
        """The movable joints' parent link → child link transforms at postures q (N, n_joints) rad / m."""
        moving = _movable_pairs(self.kin)
        pairs, T = _all_chain_transforms(self.kin, q)
        keep = [i for i, p in enumerate(pairs) if p in moving]
        return [pairs[i] for i in keep], T[:, keep]


def _urdf_fixed(urdf: str) -> list[tuple[str, str, np.ndarray]]:
    """Every fixed joint of the URDF: (parent link, child link, origin 4×4)."""
    out = []
    for j in ET.fromstring(urdf.encode()).findall("joint"):
        if j.get("type") != "fixed" or j.find("parent") is None or j.find("child") is None:
            continue
        o = j.find("origin")
        T = np.eye(4)
        if o is not None:
            T[:3, 3] = [float(v) for v in (o.get("xyz") or "0 0 0").split()]
            T[:3, :3] = matrix_of_rpy(*[float(v) for v in (o.get("rpy") or "0 0 0").split()])
        out.append((j.find("parent").get("link"), j.find("child").get("link"), T))
    return out


def _chains(kin):
    """(UrdfArm of each chain root → tip, its column indices in the read joints, its tool frame name)."""
    from pipeline.models.urdf_arm import UrdfArm

    descs = getattr(kin, "descs", None)
    if descs is None:
        return [(kin, None, TOOL_FRAME)]
    several = len(descs) > 1
    return [(UrdfArm(d), d, f"{TOOL_FRAME}_{d.tip}" if several else TOOL_FRAME) for d in descs]


def _all_chain_transforms(kin, q: np.ndarray) -> tuple[list[tuple[str, str]], np.ndarray]:
    """Every chain's transforms (`pipeline.recording.scene.chain_transforms`), each child once."""
    q = np.atleast_2d(np.asarray(q, float))
    if hasattr(kin, "expand"):
        qf = kin.expand(q)
        col = {j.name: i for i, j in enumerate(kin.all_joints)}
    pairs: list[tuple[str, str]] = []
    mats: list[np.ndarray] = []
    seen: set[str] = set()
    for arm, d, tool in _chains(kin):
        qa = q if d is None else qf[:, [col[j.name] for j in d.movable]]
        ps, T = chain_transforms(arm, qa)
        for k, (a, b) in enumerate(ps):
            b = tool if b == TOOL_FRAME else b
            if b not in seen:
                seen.add(b)
                pairs.append((a, b))
                mats.append(T[:, k])
    return pairs, np.stack(mats, axis=1)


def _movable_pairs(kin) -> set[tuple[str, str]]:
    descs = getattr(kin, "descs", None) or [kin.desc]
    return {(j.parent, j.child) for d in descs for j in d.movable}


def robot_frames(metadata: dict) -> RobotFrames | None:
    """The `RobotFrames` of a recording's metadata (a URDF chain or tree, or seed 000's D-H arm written as
    a URDF), or None for a robot without a serial chain (the Delta)."""
    from pipeline.recording.scene import description, tree_description

    kin = tree_description(metadata)
    if kin is not None:
        text = kin.urdf
    else:
        found = description(metadata)
        if found is None:
            return None
        kin, text = found
    q0 = np.zeros((1, len(kin.joint_names)))
    pairs, T = _all_chain_transforms(kin, q0)
    moving = _movable_pairs(kin)
    static = {b: (a, b, T[0, k]) for k, (a, b) in enumerate(pairs) if (a, b) not in moving}
    for a, b, M in _urdf_fixed(text):
        static.setdefault(b, (a, b, M))
    return RobotFrames(text, list(kin.joint_names), list(static.values()), kin)
