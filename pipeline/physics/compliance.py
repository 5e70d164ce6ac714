"""Compliance under gravity as terms of the calibrated model: which terms, their loads, their file.

Two families (parameters of `pipeline.measurements.tree_point.TreePointModel`, rad/(N·m)):

* ``joint-compliance``: a revolute joint turns by c · τ, τ the axial gravity moment it carries
  (N·m); its physical reading is the stiffness k = 1/c (N·m/rad);
* ``lateral-compliance``: a revolute joint's child frame tilts about the two axes normal to its
  axis by c · τ⊥ (bearing play under load, link bending);
* ``load-compliance``: a joint's compliance changes with its load, c + h·|τ| (h in rad/(N·m)²; a harmonic
  drive stiffens as its load grows: h < 0), so it turns by c·τ + h·τ·|τ|.

`physics` choices (`robocal calibrate/run --physics`): ``auto`` offers every family to the
held-out model selection (a family is kept only when it lowers the held-out error, like every
geometric parameter group) — both compliance families where the URDF has masses, and the reading
errors of `pipeline.physics.encoder` (eccentricity, scale, coupling) wherever the model carries
physics terms; ``none`` keeps the model rigid; a comma list of `FAMILIES` fits those families always
(``backlash`` needs each measurement's direction of approach; without it, it is only noted).  Candidate joints: revolute joints whose
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
from pipeline.physics.encoder import BACKLASH_ABSENT, FAMILIES as ENCODER
from pipeline.physics.gravity import G_M_S2, Load, gravity_load, has_inertials

GRAVITY = ("joint-compliance", "lateral-compliance", "load-compliance")
FAMILIES = GRAVITY + ENCODER  # the reading errors end with backlash
MIN_LOAD_NM = 1.0
EQUILIBRIUM = "first order: gravity loads evaluated at the joint readings (nominal geometry)"
SCHEMA_VERSION = 2

_CACHE: dict[tuple, Load] = {}
_ROWS: dict[tuple, dict[bytes, tuple[np.ndarray, np.ndarray]]] = {}  # per robot and payload: posture → loads


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
    """Gravity load on every movable joint of `tree` (`UrdfTree.all_joints` order) at readings q (n, n_joints).

    Cached per posture: the rows of a campaign's subsets (cross-validation folds, model-selection rounds)
    are computed by Pinocchio once, whichever subset asks first."""
    q = np.ascontiguousarray(q, float)
    h = (tree.urdf, repr((tree.coupled, payload, q.shape)), hashlib.sha256(q.tobytes()).hexdigest())
    hit = _CACHE.get(h)
    if hit is None:
        names = [j.name for j in tree.all_joints]
        key = (tree.urdf, repr((tree.coupled, payload, names)))
        rows = _ROWS.setdefault(key, {})
        keys = [r.tobytes() for r in q]
        todo = sorted({k: i for i, k in enumerate(keys) if k not in rows}.values())
        if todo:
            full = tree.expand(q[todo])[:, :len(names)]
            new = gravity_load(tree.urdf, names, full, payload=[(m, ln, np.asarray(c)) for m, ln, c in payload])
            for r, i in enumerate(todo):
                rows[keys[i]] = (new.axial[r], new.lateral[r])
        nj = len(names)
        hit = Load(np.array([rows[k][0] for k in keys]).reshape(len(q), nj),
                   np.array([rows[k][1] for k in keys]).reshape(len(q), nj, 2))
        if len(_CACHE) > 32:
            _CACHE.clear()
        if len(_ROWS) > 8:
            _ROWS.clear()
            _ROWS[key] = rows
        _CACHE[h] = hit
    return hit


def candidates(tree, q: np.ndarray, families: tuple[str, ...], payload: tuple = (),
               source: str = "URDF") -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(joints with a torsional compliance term, joints with lateral terms) for `families`."""
    families = tuple(f for f in families if f in GRAVITY)
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
    return (axial if {"joint-compliance", "load-compliance"} & set(families) else ()), \
        (lateral if "lateral-compliance" in families else ())


def document(model, x: np.ndarray, std: np.ndarray | None = None, free: np.ndarray | None = None) -> dict:
    """The physics sidecar (`schemas/model_physics.schema.json`): every term's value and σ, each compliance's
    stiffness and its σ (first order: σ_k = σ_c / c²), the families asked for but not carried by the data."""
    from pipeline.physics.encoder import describe, is_encoder

    names = model.parameter_names()
    terms = []
    for i, n in enumerate(names):
        if not (n.endswith((".compliance", ".lateral1", ".lateral2", ".compliance_load")) or is_encoder(n)):
            continue
        if free is not None and not free[i]:
            continue
        joint, kind = n.rsplit(".", 1)
        c = float(x[i])
        s = float(std[i]) if std is not None and np.isfinite(std[i]) else None
        if c == 0.0 and std is None:  # held at the nominal (not kept by the model selection)
            continue
        if is_encoder(n):
            t = describe(model.kin, n, c, s)
            t.pop("reading")
            terms.append(t)
            continue
        if kind == "compliance_load":  # the compliance's change per N·m of load
            t = {"joint": joint, "family": "load-compliance", "axis": "joint", "compliance_per_load_rad_per_Nm2": c}
            if s is not None:
                t["compliance_per_load_std_rad_per_Nm2"] = s
            terms.append(t)
            continue
        t = {"joint": joint, "family": "joint-compliance" if kind == "compliance" else "lateral-compliance",
             "axis": "joint" if kind == "compliance" else ("normal1" if kind == "lateral1" else "normal2"),
             "compliance_rad_per_Nm": c, "stiffness_Nm_per_rad": (1.0 / c) if c > 0 else None}
        if s is not None:
            t["compliance_std_rad_per_Nm"] = s
            t["stiffness_std_Nm_per_rad"] = s / c**2 if c > 0 else None
        terms.append(t)
    return {"schema": "robocal.model_physics", "version": SCHEMA_VERSION, "gravity_m_s2": G_M_S2,
            "gravity_frame": "root link, −z", "root": model.kin.root, "equilibrium": EQUILIBRIUM,
            "payload": [{"mass_kg": m, "link": ln, "com_m": list(c)} for m, ln, c in model.payload],
            "normals": "e1, e2 ⟂ the joint axis in the joint frame: e1 = normalize(a × axis), a = x unless the "
                       "axis is within 25.8° of x (then y); e2 = axis × e1",
            "readings": "encoder terms: the true angle of read joint J is q + a·sin q + b·cos q + s·q + κ·q(driver) "
                        "+ b_play·d/2, q its reading (rad), d its direction of approach (±1, 0 unknown), "
                        "before the couplings",
            "not_fitted": [{"family": f, "reason": BACKLASH_ABSENT} for f in getattr(model, "absent", ())],
            "terms": terms}


def to_yaml(doc: dict) -> str:
    import yaml

    return "# robocal physics sidecar: what the URDF cannot carry (see schemas/model_physics.schema.json)\n" + \
        yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)
