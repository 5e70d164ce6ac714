"""Touch campaigns with concealed physics: library effects injected into the TRUE robot.

Same controller as `pipeline.simulate.arc_welder` (nominal IK to an approach pose, search
along the nominal face normal, contact decided by the true robot), but the true robot also
has the effects of `pipeline.diagnose.library.term` (compliance under gravity and payload,
backlash, harmonics, scale, wrist coupling, thermal drift, trigger pretravel and latency, face
offsets, and the out-of-library `bump`), and the campaign can vary what exposes them
(payloads, search speeds, face order, a warm-up logged or not by a temperature sensor —
`pipeline.simulate.thermal`).  The recording carries only what a controller logs
(and the payload schedule the integrator programmed); the injected effects go to TRUTH.json.

The expensive part — IK of the approach poses — is `plan_targets`; `run` re-runs only the
contact search, so a benchmark can reuse one target set over many seeds.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np

from pipeline.diagnose.library.gravity import gravity_torque
from pipeline.diagnose.library.term import joint_offsets
from pipeline.diagnose.library.thermal import thermal_drift_effect
from pipeline.diagnose.library.touch import effect_by_name
from pipeline.diagnose.adapters.touch_table import add_context, last_motion_sign
from pipeline.identify.identifiability import analyse
from pipeline.models import ik, serial_arm
from pipeline.models.jig import Jig
from pipeline.models.serial_arm import SerialArm
from pipeline.plan.doptimal import woodbury_update
from pipeline.simulate import thermal
from pipeline.simulate.arc_welder import IK_SEEDS, Campaign, Noise, SimResult, _quantise, _targets, _timeline
from pipeline.systems.arc_welder import TouchModel


@dataclass(frozen=True)
class Injected:
    """An effect to inject: library name, location (or None when unique), parameter values (SI)."""

    name: str
    values: tuple[float, ...]
    location: str | None = None

    @property
    def label(self) -> str:
        return f"{self.name}@{self.location}" if self.location else self.name


def parse_effect(spec: str) -> Injected:
    """``NAME=VALUE[,VALUE…][@LOCATION]``, e.g. ``joint_compliance=4e-6@J2``, ``bump=3e-4@J2:0.6``."""
    name, eq, rest = spec.partition("=")
    if not eq or not name:
        raise ValueError(f"effect {spec!r}: expected NAME=VALUE[@LOCATION]")
    vals, _, loc = rest.partition("@")
    try:
        values = tuple(float(v) for v in vals.split(","))
    except ValueError:
        raise ValueError(f"effect {spec!r}: values must be numbers") from None
    return Injected(name.strip(), values, loc.strip() or None)


@dataclass(frozen=True)
class Variations:
    """What the campaign varies to expose effects (defaults: the plain campaign)."""

    payloads_kg: tuple[float, ...] = ()  # cycled in blocks of `payload_block` contacts; () = robot model's payload
    payload_block: int = 10
    search_speeds_m_s: tuple[float, ...] = ()  # drawn per contact; () = campaign.search_speed_m_s
    face_order: str = "shuffled"  # "shuffled" | "blocked" (all contacts of a face in one block)
    # thermal (pipeline.simulate.thermal): warm-up (τ s, ΔT∞ K) — thermal_drift is then g·ΔT in m/K —
    # and whether a temperature sensor is logged on /arm/temperature
    warm_up: tuple[float, ...] = ()
    temperature_sensor: bool = False
    payload_pairs: bool = False  # each block of targets touched once per payload (same points, payload changed)


@dataclass
class Targets:
    """IK'd candidate targets in campaign order (more than needed: some miss the face)."""

    faces: np.ndarray
    q_a: np.ndarray
    dq: np.ndarray  # rad per m of search travel
    axis: np.ndarray
    sign: np.ndarray


def _plan_batch(nominal: SerialArm, jig: Jig, campaign: Campaign, n_try: int, rng) -> Targets:
    xn = nominal.vector()
    faces, P, R = _targets(jig, n_try, rng, campaign.approach_offset_m, campaign.max_tilt_rad)
    q_a, ok = ik.solve(xn, P, R, IK_SEEDS, nominal.lower, nominal.upper, iters=40)
    faces, q_a = faces[ok], q_a[ok]
    normals = np.stack([jig.faces[f].normal for f in faces])
    Jp = ik.pose_jacobian(xn, q_a)
    twist = np.concatenate([-normals, np.zeros_like(normals)], axis=1)
    dq = np.linalg.solve(Jp, twist[..., None])[..., 0]
    axis = np.array([jig.faces[f].axis_index for f in faces], int)
    sign = np.array([jig.faces[f].normal_sign for f in faces], float)
    return Targets(faces, q_a, dq, axis, sign)


def plan_targets(nominal: SerialArm, jig: Jig, campaign: Campaign, truth: SerialArm | None = None,
                 spare: float = 1.25, payloads_kg: tuple[float, ...] = (), pool: float = 3.0,
                 geometry_weight: float = 0.0) -> Targets:
    """Approach poses (the expensive IK), seeded by campaign.seed.  With `truth`, targets whose
    search would miss the true face are screened out and batches are added until there are
    `spare`× the wanted contacts.  With `payloads_kg` (a payload-paired campaign, each point
    touched once per payload) `pool`× the wanted points are planned and the D-optimal subset
    for the geometry and every joint's gravity compliance is kept (`compliance_design`)."""
    if payloads_kg:
        n_points = -(-campaign.contacts // len(payloads_kg))
        wide = plan_targets(nominal, jig, replace(campaign, contacts=int(np.ceil(n_points * pool))), truth, spare)
        pick = compliance_design(nominal, wide, payloads_kg, int(np.ceil(n_points * spare)), campaign.approach_offset_m,
                                 geometry_weight=geometry_weight)
        return Targets(*(getattr(wide, k)[np.sort(pick)] for k in ("faces", "q_a", "dq", "axis", "sign")))
    rng = np.random.default_rng(campaign.seed)
    want = int(np.ceil(campaign.contacts * spare))
    parts: list[Targets] = []
    for _ in range(12):
        have = sum(p.faces.size for p in parts)
        if have >= want:
            break
        t = _plan_batch(nominal, jig, campaign, int((want - have) * (1.9 if truth is not None else 1.0)) + 8, rng)
        if truth is not None:
            t = _screen(t, truth, jig, campaign)
        parts.append(t)
    return Targets(*(np.concatenate([getattr(p, k) for p in parts]) for k in ("faces", "q_a", "dq", "axis", "sign")))


def compliance_design(nominal: SerialArm, t: Targets, payloads_kg: tuple[float, ...], m: int,
                      travel_m: float = 0.04, ridge: float = 1e-6, geometry_weight: float = 0.0) -> np.ndarray:
    """Indices of m targets, each touched once per payload, chosen greedily for the most
    information on the gravity compliance of every loaded joint *after* the geometry
    (Ds-optimal: log det M − log det M_geometry, the geometry a nuisance; `geometry_weight` w
    blends in D-optimality: log det M − (1 − w)·log det M_geometry), from the nominal model with
    contacts `travel_m` along the search — what the planner can know beforehand."""
    xn = nominal.vector()
    q = t.q_a + travel_m * t.dq
    model = TouchModel(nominal)
    tab = {"joint_positions": q, "axis": t.axis, "coordinate": np.zeros(t.axis.size)}
    Jg = model.jacobian(xn, tab)[:, 0, :]
    Jg = Jg[:, analyse(Jg, model.parameter_names(), priority=model.priority()).free]
    _, Jq = serial_arm.joint_jacobian(xn, q)
    jq = Jq[np.arange(q.shape[0]), t.axis]  # (N, n_joints) m/rad along the measured axis
    C = np.stack([jq * gravity_torque(nominal, xn, q, p) for p in payloads_kg], axis=1)  # (N, P, n_joints)
    loaded = np.sqrt(np.einsum("npj,npj->j", C, C))
    C = C[:, :, loaded > 1e-6 * loaded.max()]  # joints gravity never loads (a vertical axis) carry nothing
    G = np.repeat(Jg[:, None, :], len(payloads_kg), axis=1)
    G, C = G / np.linalg.norm(G, axis=(0, 1)), C / np.linalg.norm(C, axis=(0, 1))
    A = np.concatenate([G, C], axis=2)
    Minv, Ginv = np.eye(A.shape[2]) / ridge, np.eye(G.shape[2]) / ridge
    eye = np.eye(len(payloads_kg))
    chosen = np.zeros(A.shape[0], bool)
    for _ in range(min(m, A.shape[0])):
        gain_g = np.linalg.slogdet(eye + np.einsum("nkp,pq,nlq->nkl", G, Ginv, G))[1]
        gain = np.linalg.slogdet(eye + np.einsum("nkp,pq,nlq->nkl", A, Minv, A))[1] - (1 - geometry_weight) * gain_g
        gain[chosen] = -np.inf
        j = int(np.argmax(gain))
        chosen[j] = True
        Minv, Ginv = woodbury_update(Minv, A[j]), woodbury_update(Ginv, G[j])
    return np.flatnonzero(chosen)


def _screen(t: Targets, truth: SerialArm, jig: Jig, campaign: Campaign) -> Targets:
    ok = _touches(t, truth.vector(), jig, campaign, np.zeros((t.faces.size, 3)),
                  np.array([jig.faces[f].coordinate for f in t.faces]))[0]
    return Targets(t.faces[ok], t.q_a[ok], t.dq[ok], t.axis[ok], t.sign[ok])


def _touches(t: Targets, xt: np.ndarray, jig: Jig, campaign: Campaign, eps: np.ndarray, c_true: np.ndarray):
    """Which targets' searches touch the true face (2 mm inside its edges), and the travel s."""
    r = np.arange(t.faces.size)

    def gap(s):
        p = serial_arm.tip_position(xt, t.q_a + s[:, None] * t.dq) + eps
        return t.sign * (p[r, t.axis] - c_true)

    s = np.zeros(r.size)
    g0 = gap(s)
    for _ in range(8):
        h = 1e-6
        s = s - gap(s) / ((gap(s + h) - gap(s - h)) / (2 * h))
    p1 = serial_arm.tip_position(xt, t.q_a + s[:, None] * t.dq)
    on_face = np.ones(r.size, bool)
    for i, f in enumerate(t.faces):
        fc = jig.faces[f]
        a, b = fc.other_axes()
        on_face[i] = (fc.extent[0][0] + 2e-3 <= p1[i, a] <= fc.extent[0][1] - 2e-3
                      and fc.extent[1][0] + 2e-3 <= p1[i, b] <= fc.extent[1][1] - 2e-3)
    good = (g0 > 0) & (s > 0) & (s < campaign.search_travel_m - 0.01) & on_face & (np.abs(gap(s)) < 1e-10)
    return good, s


@dataclass
class EffectSim:
    """A simulated campaign with effects: what the controller logged, and the truth kept apart."""

    sim: SimResult
    payload_schedule: list[dict]
    search_speeds: np.ndarray  # (n,) m/s per contact
    injected: list[Injected]
    variations: Variations
    face_errors_m: dict[str, float] = field(default_factory=dict)
    temperature: thermal.Readings | None = None  # the /arm/temperature channel, when a sensor is logged
    kept: np.ndarray | None = None  # indices of the targets (as given) that ran to a contact, in contact order


def _resolve(injected, arm, jig):
    dummy = {"face": np.array([f.id for f in jig.faces])}
    out = []
    for e in injected:
        eff = effect_by_name(arm, dummy, e.name, e.location, jig.tolerance_m)
        if len(e.values) != eff.k:
            raise ValueError(f"effect {e.label}: {eff.k} value(s) expected ({', '.join(eff.parameters)})")
        out.append((eff, np.array(e.values, float)))
    return out


def run(nominal: SerialArm, truth: SerialArm, jig: Jig, targets: Targets, campaign: Campaign = Campaign(),
        noise: Noise = Noise(), injected: tuple[Injected, ...] | list[Injected] = (),
        variations: Variations = Variations(), seed: int | None = None, planned: bool = False) -> EffectSim:
    """Run the contact searches on planned targets with the effects in the true robot.  `planned`:
    the targets are an executed campaign — every one is run, those that find no contact are
    misses (`EffectSim.kept` says which ran to a contact), `campaign.contacts` is ignored."""
    rng = np.random.default_rng(campaign.seed + 7919 if seed is None else seed)
    xt = truth.vector()
    k = noise.scale
    eff = _thermal_retarget(_resolve(injected, truth, jig), variations)
    face_err = {f.id: float(k * rng.uniform(-noise.jig_error_m, noise.jig_error_m)) for f in jig.faces}
    for e, th in eff:
        if e.name == "face_offset":
            face_err[e.location] += float(th[0])
    latency = sum(float(th[0]) for e, th in eff if e.name == "trigger_latency")
    joint_eff = [(e, th) for e, th in eff if e.where == "joint"]
    tip_eff = [(e, th) for e, th in eff if e.where == "tip" and e.name != "trigger_latency"]

    order = np.arange(targets.faces.size)
    if variations.face_order == "blocked":
        order = order[np.argsort(targets.faces, kind="stable")]
    elif variations.face_order != "shuffled":
        raise ValueError(f"face order {variations.face_order!r}: expected shuffled or blocked")
    faces, q_a, dq = targets.faces[order], targets.q_a[order], targets.dq[order]
    axis, sign = targets.axis[order], targets.sign[order]
    m = faces.size
    eps = rng.normal(0, k * noise.repeatability_3sigma_m / 3, (m, 3))
    c_true = np.array([jig.faces[f].coordinate + face_err[jig.faces[f].id] for f in faces])
    ids = np.array([jig.faces[f].id for f in faces])

    def search(rows, extra_q, extra_tip):
        """Newton on the search travel s until the (true) wire touches the true face."""
        r = np.arange(rows.size)

        def gap(s):
            q = q_a[rows] + s[:, None] * dq[rows]
            p = serial_arm.tip_position(xt, q + extra_q(q)) + eps_k + extra_tip
            return sign[rows] * (p[r, axis[rows]] - c_true[rows])

        s = np.zeros(rows.size)
        for _ in range(8):
            h = 1e-6
            s = s - gap(s) / ((gap(s + h) - gap(s - h)) / (2 * h))
        return s

    # pass 1: which targets yield a contact (geometry only; the effects are far below the margins)
    good, s1 = _touches(Targets(faces, q_a, dq, axis, sign), xt, jig, campaign, eps, c_true)
    pairs = bool(variations.payload_pairs and variations.payloads_kg)
    n_points = -(-campaign.contacts // len(variations.payloads_kg)) if pairs else campaign.contacts
    keep = np.flatnonzero(good)[:n_points] if not planned else np.flatnonzero(good)
    if planned and (pairs or not keep.size):
        raise RuntimeError("a planned campaign runs its own targets (no --payload-pairs), and needs one that lands")
    if keep.size < n_points and not planned:
        raise RuntimeError(f"only {keep.size} of {n_points} targets touch the jig; plan more targets")
    payload_idx = None
    if pairs:  # block b of points, touched with payload 0, then 1, …: [b0·p0, b0·p1, b1·p0, b1·p1, …]
        blk = max(variations.payload_block, 1)
        chunks = [keep[i:i + blk] for i in range(0, keep.size, blk)]
        np_ = len(variations.payloads_kg)
        keep = np.concatenate([c for c in chunks for _ in range(np_)])[:campaign.contacts]
        payload_idx = np.concatenate([np.full(c.size, p) for c in chunks for p in range(np_)])[:campaign.contacts]
    n = keep.size
    speeds = (rng.choice(np.asarray(variations.search_speeds_m_s, float), n) if variations.search_speeds_m_s
              else np.full(n, campaign.search_speed_m_s))
    eps_k = eps[keep]
    if pairs:  # a repeated point gets its own repeatability error
        first = np.zeros(n, bool)
        first[np.unique(keep, return_index=True)[1]] = True
        eps_k[~first] = rng.normal(0, k * noise.repeatability_3sigma_m / 3, ((~first).sum(), 3))
    camp_v = replace(campaign, search_speed_m_s=speeds)  # _timeline divides the travel elementwise
    # first timeline: contact times and the direction each joint last moved (the physical state)
    t_ns, q_stream, t_c = _timeline(q_a[keep], dq[keep], s1[keep], camp_v, nominal.n_joints)
    payload_schedule = []
    payload = np.full(n, truth.payload_kg)
    if variations.payloads_kg:
        blk = np.arange(n) // max(variations.payload_block, 1)
        payload = np.asarray(variations.payloads_kg, float)[blk % len(variations.payloads_kg) if payload_idx is None
                                                            else payload_idx]
    ctx = {"joint_positions": q_a[keep] + s1[keep, None] * dq[keep], "axis": axis[keep], "face": ids[keep],
           "normal_sign": sign[keep], "payload_kg": payload, "time_since_start_s": (t_c - t_ns[0]) * 1e-9,
           "last_motion_sign": last_motion_sign(t_ns, q_stream, t_c), **_thermal_context(variations, t_c, t_ns)}

    def extra_q(q):
        return joint_offsets(joint_eff, truth, xt, {**ctx, "joint_positions": q}) if joint_eff else 0.0

    extra_tip = np.zeros((n, 3))
    for e, th in tip_eff:
        extra_tip += np.einsum("nik,k->ni", e.basis(truth, xt, ctx), th)
    # pass 2: the searches of the true robot with its effects; the latch comes `latency` late
    s2 = search(keep, extra_q, extra_tip)  # (rows = keep; eps_k is already per contact)
    s_latch = s2 + speeds * latency
    quant = k > 0
    q_latch = _quantise(q_a[keep] + s_latch[:, None] * dq[keep], noise.encoder_counts_per_rev, quant)
    t_ns, q_stream, t_c = _timeline(q_a[keep], dq[keep], s_latch, camp_v, nominal.n_joints)
    q_stream = _quantise(q_stream, noise.encoder_counts_per_rev, quant)
    if variations.payloads_kg:
        change = np.flatnonzero(np.r_[True, np.diff(payload) != 0])
        payload_schedule = [{"t_ns": int(t_c[i] - int(campaign.dwell_s * 1e9) - 1), "payload_kg": float(payload[i])}
                            for i in change]
        payload_schedule[0]["t_ns"] = int(t_ns[0])
    coord = np.array([jig.faces[f].coordinate for f in faces[keep]])
    p_rec = serial_arm.tip_position(xt, q_latch)
    injected_n = p_rec[np.arange(n), axis[keep]] - coord
    sim = SimResult(stream_t_ns=t_ns, stream_q=q_stream, contact_t_ns=t_c, contact_q=q_latch,
                    contact_face=list(ids[keep]), contact_axis=axis[keep], contact_coordinate=coord,
                    injected_along_normal_m=injected_n, face_errors_m=face_err, dropped_targets=int(m - n))
    return EffectSim(sim=sim, payload_schedule=payload_schedule, search_speeds=speeds, injected=list(injected),
                     variations=variations, face_errors_m=face_err, kept=order[keep],
                     temperature=_thermal_readings(variations, t_ns, campaign.seed + 7919 if seed is None else seed, k))


# ----- thermal: warm-up and temperature sensor (pipeline.simulate.thermal) ------------------
def _warm(variations: Variations) -> thermal.WarmUp | None:
    return thermal.WarmUp(*variations.warm_up) if variations.warm_up else None


def _thermal_retarget(eff: list, variations: Variations) -> list:
    """With a warm-up, thermal_drift follows the true temperature rise (values in m/K)."""
    if _warm(variations) is None:
        return eff
    as_temp = thermal_drift_effect({"temperature_rise_K": np.zeros(1), "temperature_sensor": np.array(["true"])})
    return [(as_temp, th) if e.name == "thermal_drift" else (e, th) for e, th in eff]


def _thermal_context(variations: Variations, t_c: np.ndarray, t_ns: np.ndarray) -> dict:
    warm = _warm(variations)
    return {} if warm is None else {"temperature_rise_K": warm.rise((t_c - t_ns[0]) * 1e-9)}


def _thermal_readings(variations: Variations, t_ns: np.ndarray, seed: int, noise_scale: float) -> thermal.Readings | None:
    """The sensor's readings over the whole stream (own random stream: other draws unchanged;
    its noise scales with `Noise.scale` like every error source)."""
    if not variations.temperature_sensor:
        return None
    sensor = replace(thermal.Sensor(), noise_k=thermal.Sensor().noise_k * noise_scale)
    return thermal.read_sensor(_warm(variations), int(t_ns[0]), int(t_ns[-1]), np.random.default_rng([seed, 271828]),
                               sensor)


def temperature_stream(es: EffectSim):
    """The logged readings as the ingest's `TemperatureStream` (None without a sensor)."""
    return None if es.temperature is None else es.temperature.stream()


def diagnosis_table(es: EffectSim, jig: Jig, default_payload_kg: float = 0.0) -> dict:
    """The diagnosis table of a simulated campaign, built only from what the recording would hold."""
    s = es.sim
    table = {"timestamp_ns": s.contact_t_ns, "joint_positions": s.contact_q, "face": np.array(s.contact_face, object),
             "axis": s.contact_axis, "coordinate": s.contact_coordinate, "record": np.arange(s.contact_t_ns.size)}
    q_stream = s.stream_q
    return add_context(table, s.stream_t_ns, q_stream, normal_sign_of={f.id: f.normal_sign for f in jig.faces},
                       payload_schedule=es.payload_schedule or None, default_payload_kg=default_payload_kg,
                       temperature=temperature_stream(es))


def campaign_metadata(es: EffectSim, campaign: Campaign) -> dict:
    """What the integrator programmed (goes into the recording's campaign metadata)."""
    meta = {"search_speeds_m_s": sorted({float(v) for v in es.search_speeds}),
            "face_order": es.variations.face_order}
    if es.payload_schedule:
        meta["payload_schedule"] = es.payload_schedule
    if es.variations.payload_pairs:
        meta["payload_pairs"] = True
    return meta


def truth_effects(es: EffectSim) -> dict:
    """The injected effects and variations, for TRUTH.json only."""
    return {"effects": [{"name": e.name, "location": e.location, "values": list(e.values)} for e in es.injected],
            "variations": asdict(es.variations), "face_errors_m": es.face_errors_m}
