"""A URDF robot in rerun the way rerun does it (rerun-sdk 0.41's URDF support, `rerun.urdf.UrdfTree`): the
robot's own URDF loaded by rerun's URDF loader — its links by their URDF names, each in its named frame
``<which>/<link>`` — and its movable joints' transforms (``UrdfJoint.compute_transform_columns``) on the
recording's ``time`` timeline, one entity per joint; ``nominal`` and ``calibrated`` side by side, each
from its own URDF (the calibrated one is model.urdf).

What is drawn (`display_urdf`): a visual mesh whose file resolves — ``package://PKG/…`` through the
``--mesh-path`` folders, ROS_PACKAGE_PATH (``DIR/PKG`` or ``DIR`` named PKG) and AMENT_PREFIX_PATH
(``PREFIX/share/PKG``); a relative path beside the URDF file the recording names — as that mesh;
otherwise (a mesh that does not resolve, or a link without visuals) primitives: a cylinder from the link's
origin to each child joint's origin and a sphere at the origin, sized to the robot's reach.  Collision
geometry is left out.  Lengths m; the robot placed in the run's ``world`` (the instrument frame) by one
static transform ``tf#/world`` → its top link (the instrument → root registration of that robot's
parameters, times the URDF's own frames from its top link down to the root).

Entities: ``world/robot_<which>/…`` (rerun's loader: ``visual_geometries/<link>/visual_<k>``;
``tf_static`` its fixed transforms), ``world/robot_<which>/joints/<joint>`` the joint transforms,
``world/robot_<which>/placement``.
"""

from __future__ import annotations

import os
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from pipeline.models.urdf import matrix_of_rpy, rpy_of

COLORS = {"nominal": "0.86 0.31 0.24 1", "calibrated": "0.24 0.43 0.78 0.6"}


def mesh_dirs(extra: list[str | Path] | tuple = ()) -> list[Path]:
    """Where ``package://`` meshes are looked for: `extra` (``--mesh-path``), ROS_PACKAGE_PATH, AMENT_PREFIX_PATH/share."""
    out = [Path(p) for p in extra]
    out += [Path(p) for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
    out += [Path(p) / "share" for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return out


def resolve_mesh(filename: str, dirs: list[Path], base: Path | None) -> Path | None:
    """The file a URDF mesh name points to, or None when it does not resolve."""
    if filename.startswith("package://"):
        pkg, _, rest = filename[len("package://"):].partition("/")
        for d in dirs:
            for cand in (d / pkg / rest, d / rest if d.name == pkg else None):
                if cand is not None and cand.is_file():
                    return cand.resolve()
        return None
    if filename.startswith("file://"):
        filename = filename[len("file://"):]
    p = Path(filename)
    if not p.is_absolute():
        p = (base or Path.cwd()) / p
    return p.resolve() if p.is_file() else None


def _origin(el) -> np.ndarray:
    T = np.eye(4)
    o = el.find("origin") if el is not None else None
    if o is not None:
        T[:3, 3] = [float(v) for v in (o.get("xyz") or "0 0 0").split()]
        T[:3, :3] = matrix_of_rpy(*[float(v) for v in (o.get("rpy") or "0 0 0").split()])
    return T


def _primitives(link, children: list[np.ndarray], radius: float, rgba: str) -> None:
    """Cylinders from the link's origin to each child joint origin, and a sphere at the origin."""
    def visual(xyz, rpy, geom, **attrs):
        v = ET.SubElement(link, "visual")
        ET.SubElement(v, "origin", {"xyz": " ".join(repr(float(a)) for a in xyz), "rpy": " ".join(repr(float(a)) for a in rpy)})
        ET.SubElement(ET.SubElement(v, "geometry"), geom, {k: repr(float(a)) for k, a in attrs.items()})
        ET.SubElement(ET.SubElement(v, "material", {"name": f"robocal_{rgba}"}), "color", {"rgba": rgba})

    visual((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), "sphere", radius=1.3 * radius)
    for p in children:
        L = float(np.linalg.norm(p))
        if L < 1e-6:
            continue
        z = p / L
        axis = np.cross([0.0, 0.0, 1.0], z)
        s, c = np.linalg.norm(axis), z[2]
        R = np.eye(3) if s < 1e-12 else _axis_angle(axis / s, np.arctan2(s, c))
        visual(tuple(p / 2), rpy_of(R), "cylinder", radius=radius, length=L)


def _axis_angle(a: np.ndarray, t: float) -> np.ndarray:
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K


def display_urdf(text: str, which: str, dirs: list[Path], base: Path | None = None) -> tuple[str, dict]:
    """(the URDF rerun loads for robot `which`, {"meshes": n resolved, "primitives": [links drawn as
    primitives]}): meshes resolved to absolute paths or replaced by primitives, collisions dropped, the
    robot renamed ``robot_<which>`` (its entity under ``world``)."""
    robot = ET.fromstring(text.encode())
    robot.set("name", f"robot_{which}")
    joints = robot.findall("joint")
    child_origins: dict[str, list[np.ndarray]] = {}
    for j in joints:
        if j.find("parent") is not None:
            child_origins.setdefault(j.find("parent").get("link"), []).append(_origin(j)[:3, 3])
    reach = sum(float(np.linalg.norm(p)) for ps in child_origins.values() for p in ps)
    radius = max(0.004, 0.015 * min(reach, 3.0))
    rgba = COLORS.get(which, "0.5 0.5 0.5 1")
    stats = {"meshes": 0, "primitives": []}
    for link in robot.findall("link"):
        for c in link.findall("collision"):
            link.remove(c)
        visuals = link.findall("visual")
        kept = 0
        for v in visuals:
            m = v.find("geometry/mesh")
            if m is None:
                kept += 1
                continue
            found = resolve_mesh(m.get("filename", ""), dirs, base)
            if found is None:
                link.remove(v)
            else:
                m.set("filename", str(found))
                kept += 1
                stats["meshes"] += 1
        if kept == 0:
            _primitives(link, child_origins.get(link.get("name"), []), radius, rgba)
            stats["primitives"].append(link.get("name"))
    return ET.tostring(robot, encoding="unicode"), stats


def _top_to(text: str, link: str) -> tuple[str, np.ndarray]:
    """(the URDF's top link above `link`, the pose of `link` in it through the joints' origins at zero)."""
    parent = {}
    for j in ET.fromstring(text.encode()).findall("joint"):
        if j.find("parent") is not None and j.find("child") is not None:
            parent[j.find("child").get("link")] = (j.find("parent").get("link"), _origin(j))
    T, f = np.eye(4), link
    while f in parent:
        p, M = parent[f]
        T = M @ T
        f = p
    return f, T


def log_urdf_robot(rec, which: str, urdf_text: str, root: str, root_in_world: np.ndarray, joints: list[str],
                   q: np.ndarray, t_ns: np.ndarray, dirs: list[Path], base: Path | None = None) -> tuple[list[str], dict]:
    """Log robot `which` (nominal | calibrated) from its URDF: the loader's links, the placement (the `root`
    link's pose in the world, 4×4, `root_in_world`) and the movable `joints`' transforms at readings q
    (N, J) rad / m on `time` t_ns (N,).  Returns (entity paths, `display_urdf`'s stats)."""
    import rerun as rr
    from rerun.urdf import UrdfTree
    from scipy.spatial.transform import Rotation

    text, stats = display_urdf(urdf_text, which, dirs, base)
    base_path = f"world/robot_{which}"
    with tempfile.TemporaryDirectory(prefix="robocal_urdf_") as d:
        f = Path(d) / f"robot_{which}.urdf"
        f.write_text(text)
        tree = UrdfTree.from_file_path(f, "world", frame_prefix=f"{which}/",
                                       static_transform_entity_path=f"{base_path}/tf_static")
        tree.log_urdf_to_recording(rec)
    top, T_top_root = _top_to(urdf_text, root)
    P = np.asarray(root_in_world, float) @ np.linalg.inv(T_top_root)
    rec.log(f"{base_path}/placement", rr.Transform3D(translation=P[:3, 3], quaternion=Rotation.from_matrix(
        P[:3, :3]).as_quat(), parent_frame="tf#/world", child_frame=f"{which}/{top}"), static=True)
    paths = [f"{base_path}/placement", f"{base_path}/tf_static"]
    paths += [p.lstrip("/") for link in _links(text) for p in tree.get_visual_geometry_paths(link)]
    time = rr.TimeColumn("time", timestamp=np.asarray(t_ns, np.int64).astype("datetime64[ns]"))
    q = np.atleast_2d(np.asarray(q, float))
    for k, name in enumerate(joints):
        j = tree.get_joint_by_name(name)
        if j is None:
            continue
        path = f"{base_path}/joints/{name}"
        rec.send_columns(path, indexes=[time], columns=j.compute_transform_columns(q[:, k].tolist(), clamp=False))
        paths.append(path)
    return paths, stats


def _links(text: str) -> list[str]:
    return [link.get("name") for link in ET.fromstring(text.encode()).findall("link")]
