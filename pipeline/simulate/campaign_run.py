"""Execute a planned touch campaign (`pipeline.plan.campaign`) on the TRUE robot.

Each measurement runs as the controller would: joint move to the campaign's approach
configuration, search at the campaign's joint rate until the *true* wire (true model +
repeatability error) meets the *true* face (drawing + machining error), latch the encoders,
retract.  A search that finds no face within its travel, or whose contact would fall off the
face's edges, is a **miss**: logged on `/touch/miss` with the encoders at the end of the
search, never replaced (the campaign is what was planned).  A wire already at or past the face
plane at the approach configuration is a miss too (`contact_at_approach`).  The controller stops
a search at the first joint limit it reaches (the nominal model's limits, as in the unplanned
simulator): a face beyond it is a miss (`no_contact`), logged at the limit, so no joint reading
ever leaves its travel.  Simplification: the search does not model touching a *different* face
after leaving its own.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pipeline.models import serial_arm
from pipeline.models.jig import Jig
from pipeline.models.serial_arm import SerialArm
from pipeline.plan.campaign import TouchCampaign
from pipeline.plan.touch import edge_distance, search
from pipeline.simulate.arc_welder import Campaign, Noise, SimResult, _quantise, _timeline


@dataclass
class Executed:
    """A campaign run on the true robot: the contacts (SimResult), and the misses."""

    sim: SimResult
    landed: np.ndarray  # (n,) bool over the campaign's measurements
    miss_index: np.ndarray  # campaign indices that missed
    miss_reason: list[str]
    miss_t_ns: np.ndarray
    miss_q: np.ndarray  # (n_miss, n_joints) encoders at the end of the search

    @property
    def land_rate(self) -> float:
        return float(self.landed.mean()) if self.landed.size else 0.0

    def miss_messages(self) -> list[tuple[str, dict]]:
        """`/touch/miss` message bodies."""
        faces = self.sim_faces
        return [("/touch/miss", {"timestamp_ns": int(t), "joint_positions": q, "face": faces[i],
                                 "campaign_index": int(i), "reason": r})
                for t, q, i, r in zip(self.miss_t_ns, self.miss_q.tolist(), self.miss_index, self.miss_reason)]

    sim_faces: list[str] | None = None


def travel_to_limits(q_a: np.ndarray, dq: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                     margin_rad: float = 1e-4) -> np.ndarray:
    """(n,) m of search travel from the approach joints `q_a` (n, J) at the joint rates `dq` (rad per m)
    before the first joint comes within `margin_rad` of its limit (inf where no joint moves); the margin
    keeps an encoder count's rounding inside the travel."""
    lower, upper = np.asarray(lower) + margin_rad, np.asarray(upper) - margin_rad
    with np.errstate(divide="ignore", invalid="ignore"):
        to = np.where(dq > 0, (upper - q_a) / dq, np.where(dq < 0, (lower - q_a) / dq, np.inf))
    return np.maximum(to.min(axis=1), 0.0)


def landing(truth_x: np.ndarray, jig: Jig, face: np.ndarray, q_a: np.ndarray, dq: np.ndarray, travel_m: float,
            eps: np.ndarray | None = None, face_err: np.ndarray | None = None, limit_m: np.ndarray | None = None):
    """Which searches touch their true face: (landed, reason code 0 hit / 1 no contact / 2 at
    approach, travel s (m)); vectorised over searches.  `face` indexes jig.faces; `limit_m` (n,) m, where
    given, the travel at which the controller stops each search (a joint limit): a contact beyond it is
    no contact."""
    axis = np.array([jig.faces[f].axis_index for f in face], int)
    sign = np.array([jig.faces[f].normal_sign for f in face], float)
    coord = np.array([jig.faces[f].coordinate for f in face]) + (0.0 if face_err is None else face_err)
    s, g0 = search(truth_x, q_a, dq, axis, sign, coord, eps, travel_m=travel_m)
    s = np.where(np.isfinite(s), s, travel_m)
    p = serial_arm.tip_position(truth_x, q_a + s[:, None] * dq) + (0.0 if eps is None else eps)
    on = edge_distance(jig, face, p) >= 0
    at_approach = g0 <= 0
    hit = ~at_approach & (s > 0) & (s < travel_m) & on
    if limit_m is not None:
        hit &= s <= limit_m
    reason = np.where(hit, 0, np.where(at_approach, 2, 1))
    return hit, reason, s


def execute(nominal: SerialArm, truth: SerialArm, jig: Jig, plan: TouchCampaign, noise: Noise = Noise(),
            seed: int = 0, start_ns: int | None = None, stream: bool = True) -> Executed:
    """Run every planned measurement in order on the true robot (see module docstring).
    `stream` False skips the encoder stream (contacts only, times from a 1 s per measurement
    clock) for benchmarks that only fit contacts."""
    rng = np.random.default_rng(seed)
    k = noise.scale
    face_err = {f.id: float(k * rng.uniform(-noise.jig_error_m, noise.jig_error_m)) for f in jig.faces}
    ids = [f.id for f in jig.faces]
    face = np.array([ids.index(f) for f in plan.face_id], int)
    n = face.size
    eps = rng.normal(0, k * noise.repeatability_3sigma_m / 3, (n, 3))
    camp: Campaign = plan.campaign if start_ns is None else replace(plan.campaign, start_ns=start_ns)
    limit = travel_to_limits(plan.q_approach, plan.dq, nominal.lower, nominal.upper)
    hit, reason, s = landing(truth.vector(), jig, face, plan.q_approach, plan.dq, camp.search_travel_m, eps,
                             np.array([face_err[ids[f]] for f in face]), limit)
    s_run = np.where(hit, s, np.where(reason == 2, 0.0, np.minimum(camp.search_travel_m, limit)))
    quant = k > 0
    q_end = _quantise(plan.q_approach + s_run[:, None] * plan.dq, noise.encoder_counts_per_rev, quant)
    if stream:
        t_ns, q_stream, t_end = _timeline(plan.q_approach, plan.dq, np.maximum(s_run, 1e-6), camp, nominal.n_joints)
        q_stream = _quantise(q_stream, noise.encoder_counts_per_rev, quant)
    else:
        t_end = camp.start_ns + np.arange(1, n + 1, dtype=np.int64) * 1_000_000_000
        t_ns, q_stream = t_end[:0], np.zeros((0, nominal.n_joints))
    h = np.flatnonzero(hit)
    axis = plan.axis[h]
    coord = np.array([jig.faces[f].coordinate for f in face[h]])
    p_rec = serial_arm.tip_position(truth.vector(), q_end[h]) if h.size else np.zeros((0, 3))
    sim = SimResult(stream_t_ns=t_ns, stream_q=q_stream, contact_t_ns=t_end[h], contact_q=q_end[h],
                    contact_face=[plan.face_id[i] for i in h], contact_axis=axis, contact_coordinate=coord,
                    injected_along_normal_m=p_rec[np.arange(h.size), axis] - coord if h.size else np.zeros(0),
                    face_errors_m=face_err, dropped_targets=int(n - h.size))
    m = np.flatnonzero(~hit)
    names = {1: "no_contact", 2: "contact_at_approach"}
    return Executed(sim=sim, landed=hit, miss_index=m, miss_reason=[names[int(r)] for r in reason[m]],
                    miss_t_ns=t_end[m], miss_q=q_end[m], sim_faces=list(plan.face_id))


def execute_with_effects(nominal: SerialArm, truth: SerialArm, jig: Jig, plan: TouchCampaign, noise: Noise,
                         seed: int, injected, variations) -> tuple:
    """Run a planned campaign on a true robot *with* library effects (`pipeline.simulate.effects`,
    `run(planned=True)`): every planned search, in the plan's order (or blocked by face), the
    effects in the contacts.  Returns (EffectSim, Executed).  Simplification: a miss takes no time
    on the timeline; it is logged just after the contact before it, with the encoders at the end of
    its search (at the approach pose when the wire already touched there)."""
    from pipeline.simulate import effects as se

    ids = [f.id for f in jig.faces]
    face = np.array([ids.index(f) for f in plan.face_id], int)
    sign = np.array([jig.faces[f].normal_sign for f in face], float)
    targets = se.Targets(face, plan.q_approach, plan.dq, plan.axis, sign)
    camp = replace(plan.campaign, contacts=plan.n, seed=seed)
    es = se.run(nominal, truth, jig, targets, camp, noise, injected, variations, planned=True)
    landed = np.zeros(plan.n, bool)
    landed[es.kept] = True
    m = np.flatnonzero(~landed)
    _, reason, _ = landing(truth.vector(), jig, face[m], plan.q_approach[m], plan.dq[m], camp.search_travel_m)
    at_approach = reason == 2
    end = np.minimum(camp.search_travel_m, travel_to_limits(plan.q_approach[m], plan.dq[m], nominal.lower, nominal.upper))
    q_end = plan.q_approach[m] + np.where(at_approach, 0.0, end)[:, None] * plan.dq[m]
    t_c = es.sim.contact_t_ns
    ks = np.argsort(es.kept)
    before = np.searchsorted(es.kept[ks], m) - 1  # the contact of the plan's row just before each miss
    t_miss = np.where(before >= 0, t_c[ks[np.maximum(before, 0)]] + 1_000_000, es.sim.stream_t_ns[0])
    ex = Executed(sim=es.sim, landed=landed, miss_index=m,
                  miss_reason=["contact_at_approach" if a else "no_contact" for a in at_approach],
                  miss_t_ns=t_miss, miss_q=q_end, sim_faces=list(plan.face_id))
    return es, ex
