"""Compliance under gravity as terms of the calibrated model: which terms, their loads, their file.

Two families (parameters of `pipeline.measurements.tree_point.TreePointModel`, rad/(N·m)):

* ``joint-compliance``: a revolute joint turns by c · τ, τ the axial gravity moment it carries
  (N·m); its physical reading is the stiffness k = 1/c (N·m/rad);
* ``lateral-compliance``: a revolute joint's child frame tilts about the two axes normal to its
  axis by c · τ⊥ (bearing play under load, link bending).

`physics` choices (`robocal calibrate/run --physics`): ``auto`` offers both families to the
held-out model selection (a family is kept only when it lowers the held-out error, like every
geometric parameter group), ``none`` keeps the model rigid, a comma list (``joint-compliance``,
``lateral-compliance``) fits those families always.  Candidate joints: revolute joints whose
gravity load varies over the campaign by at least `MIN_LOAD_NM` (RMS about its mean) — a constant
load is a joint offset, not something the data can name.

Loads are evaluated at the joint readings (first order in the deflection: the load at the deflected
configuration differs by c·τ·∂τ/∂q, ≈ 0.5 % of the deflection for a few mrad); `EQUILIBRIUM` says so
in every output.
"""

from __future__ import annotations

import hashlib

import numpy as np

from pipeline.errors import RobocalError
from pipeline.physics.gravity import G_M_S2, Load, gravity_load, has_inertials

FAMILIES = ("joint-compliance", "lateral-compliance")
MIN_LOAD_NM = 1.0
EQUILIBRIUM = "first order: gravity loads evaluated at the joint readings (nominal geometry)"
SCHEMA_VERSION = 1

_CACHE: dict[tuple, Load] = {}


def parse_spec(text: str | None) -> tuple[str, tuple[str, ...]]:
    """('auto' | 'none' | 'fixed', families) of a --physics value."""
    t = (text or "auto").strip().lower()
    if t in ("auto", "none"):
        return t, (FAMILIES if t == "auto" else ())
    fams = tuple(f.strip() for f in t.split(",") if f.strip())
    bad = [f for f in fams if f not in FAMILIES]
    if bad or not fams:
        raise RobocalError(f"--physics {text!r}: expected auto, none or a comma list of {', '.join(FAMILIES)}")
    return "fixed", fams


def parse_payload(items) -> tuple:
    """`KG@LINK` or `KG@LINK:X,Y,Z` (centre of mass in the link frame, m) → ((kg, link, (x, y, z)), …)."""
    out = []
    for it in items or ():
        mass, sep, rest = str(it).partition("@")
        link, _, com = rest.partition(":")
        try:
            m = float(mass)
            c = tuple(float(v) for v in com.split(",")) if com else (0.0, 0.0, 0.0)
        except ValueError:
            raise RobocalError(f"--payload {it!r}: expected KG@LINK or KG@LINK:X,Y,Z (m)") from None
        if not sep or not link or len(c) != 3 or not (np.isfinite(m) and 0 < m < 1e4) or not np.all(np.isfinite(c)):
            raise RobocalError(f"--payload {it!r}: expected KG@LINK or KG@LINK:X,Y,Z with 0 < KG < 10000")
        out.append((m, link, c))
    return tuple(out)


def loads(tree, q: np.ndarray, payload: tuple = ()) -> Load:
    """Gravity load on every movable joint of `tree` (`UrdfTree.all_joints` order) at readings q (n, n_joints)."""
    q = np.ascontiguousarray(q, float)
    h = (tree.urdf, repr((tree.coupled, payload, q.shape)), hashlib.sha256(q.tobytes()).hexdigest())
    hit = _CACHE.get(h)
    if hit is None:
        names = [j.name for j in tree.all_joints]
        full = tree.expand(q)[:, :len(names)]
        hit = gravity_load(tree.urdf, names, full, payload=[(m, ln, np.asarray(c)) for m, ln, c in payload])
        if len(_CACHE) > 32:
            _CACHE.clear()
        _CACHE[h] = hit
    return hit


def candidates(tree, q: np.ndarray, families: tuple[str, ...], payload: tuple = (),
               source: str = "URDF") -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(joints with a torsional compliance term, joints with lateral terms) for `families`."""
    if not families:
        return (), ()
    if not has_inertials(tree.urdf):
        raise RobocalError(f"{source}: no link has an <inertial> mass: gravity terms ({', '.join(families)}) "
                           "need the robot's masses (use --physics none)")
    load = loads(tree, q, payload)
    revolute = [i for i, j in enumerate(tree.all_joints) if j.type in ("revolute", "continuous")]
    names = [j.name for j in tree.all_joints]
    varies = lambda a: float(np.sqrt(np.mean((a - a.mean(0)) ** 2)))  # noqa: E731
    axial = tuple(names[i] for i in revolute if varies(load.axial[:, i]) >= MIN_LOAD_NM)
    lateral = tuple(names[i] for i in revolute if max(varies(load.lateral[:, i, 0]), varies(load.lateral[:, i, 1]))
                    >= MIN_LOAD_NM)
    return (axial if "joint-compliance" in families else ()), (lateral if "lateral-compliance" in families else ())


def document(model, x: np.ndarray, std: np.ndarray | None = None, free: np.ndarray | None = None) -> dict:
    """The physics sidecar (`schemas/model_physics.schema.json`): every term's value, σ and stiffness."""
    names = model.parameter_names()
    terms = []
    for i, n in enumerate(names):
        if not n.endswith((".compliance", ".lateral1", ".lateral2")):
            continue
        if free is not None and not free[i]:
            continue
        joint, kind = n.rsplit(".", 1)
        c = float(x[i])
        if c == 0.0 and std is None:  # held at the rigid nominal (not kept by the model selection)
            continue
        t = {"joint": joint, "family": "joint-compliance" if kind == "compliance" else "lateral-compliance",
             "axis": "joint" if kind == "compliance" else ("normal1" if kind == "lateral1" else "normal2"),
             "compliance_rad_per_Nm": c, "stiffness_Nm_per_rad": (1.0 / c) if c > 0 else None}
        if std is not None:
            t["compliance_std_rad_per_Nm"] = float(std[i])
        terms.append(t)
    return {"schema": "robocal.model_physics", "version": SCHEMA_VERSION, "gravity_m_s2": G_M_S2,
            "gravity_frame": "root link, −z", "root": model.kin.root, "equilibrium": EQUILIBRIUM,
            "payload": [{"mass_kg": m, "link": ln, "com_m": list(c)} for m, ln, c in model.payload],
            "normals": "e1, e2 ⟂ the joint axis in the joint frame: e1 = normalize(a × axis), a = x unless the "
                       "axis is within 25.8° of x (then y); e2 = axis × e1",
            "terms": terms}


def to_yaml(doc: dict) -> str:
    import yaml

    return "# robocal physics sidecar: what the URDF cannot carry (see schemas/model_physics.schema.json)\n" + \
        yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)
