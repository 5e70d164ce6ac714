"""Candidate contacts of the arc-welder (seed 000) for pose planning.

A candidate is a contact: an approach pose over a jig face, reached by the nominal inverse
kinematics, and the search along the face normal until the wire touches.  They are made by
the campaign simulator itself run with the *nominal* model as truth and no noise — i.e. the
contacts the controller expects — so planning needs no measurement and no truth.
"""

from __future__ import annotations

import numpy as np

from pipeline.models.jig import Jig, stepped_block
from pipeline.plan.approach import backlash_columns, document_balance
from pipeline.simulate.arc_welder import Campaign, Noise, SimResult, simulate
from pipeline.systems import arc_welder as aw


def table_of(sim: SimResult) -> dict[str, np.ndarray]:
    """A simulated campaign's contacts as a TouchModel measurement table."""
    n = sim.contact_t_ns.size
    return {"timestamp_ns": sim.contact_t_ns, "joint_positions": sim.contact_q, "axis": sim.contact_axis,
            "coordinate": sim.contact_coordinate, "face": np.array(sim.contact_face, dtype=object),
            "record": np.arange(n)}


def candidates(n: int, seed: int = 0, jig: Jig | None = None) -> tuple[aw.TouchModel, dict[str, np.ndarray]]:
    """(nominal measurement model, table of n candidate contacts)."""
    nominal = aw.nominal_arm()
    sim = simulate(nominal, nominal, jig or stepped_block(), Campaign(contacts=n, seed=seed), Noise(scale=0.0))
    return aw.TouchModel(nominal), table_of(sim)


def measured(n: int, seed: int, random_errors: bool = False, noise_scale: float = 1.0):
    """A simulated *measured* campaign (true model ≠ nominal, with noise): (model, table).
    For checking a plan on simulated data; the planner itself only sees joint configs and faces."""
    nominal = aw.nominal_arm()
    truth = aw.random_truth(nominal, np.random.default_rng(seed + 1_000_003)) if random_errors else aw.reference_truth()
    sim = simulate(nominal, truth, stepped_block(), Campaign(contacts=n, seed=seed), Noise(scale=noise_scale))
    return aw.TouchModel(nominal), table_of(sim)


def touch_campaign(n_candidates: int, m: int, seed: int = 0, margin_m: float = 0.010, stages: int = 1,
                   first_stage: int = 15, after=None, sigma_m: float = 5e-5, backlash: bool = False) -> dict:
    """An executable campaign document (`pipeline.plan.campaign`): one stage D-optimal with the
    face margin (`backlash`: D-optimal for the geometry and every joint's backlash together,
    `approach.backlash_columns`); with `stages` 2 the first stage (`pipeline.plan.staged`); with `after`
    (a run directory of the stages so far) the next stage, planned on its MAP-updated model."""
    import time

    from pipeline.identify.model import take
    from pipeline.plan import staged, touch
    from pipeline.plan.campaign import touch_document
    from pipeline.plan.select import plan
    from pipeline.simulate.arc_welder import Campaign

    if backlash and (stages != 1 or after is not None):
        from pipeline.errors import RobocalError

        raise RobocalError("--backlash plans one-stage campaigns (not with --stages 2 or --after)")
    jig = stepped_block()
    nominal = aw.nominal_arm()
    campaign = Campaign()
    if after is not None:
        nominal, jig, table = stages_so_far(after)
        x, cov = staged.map_fit(aw.TouchModel(nominal), table, staged.prior_cov(nominal), sigma_m)
        arm = nominal.with_vector(x)
        pool = touch.pool(arm, jig, n_candidates, seed, margin_m, campaign)
        t1 = time.perf_counter()
        idx, p = staged.plan_next_stage(x, cov, jig, pool, m, sigma_m, campaign.approach_offset_m,
                                        prior=staged.prior_cov(nominal))
        doc = touch_document(aw.SYSTEM, arm, jig, pool.take(idx), campaign, margin_m, 2, 2, idx)
        extra = {"criterion": "I-optimal (least mean predicted 3-D tool-point variance over the jig) given the "
                              "earlier stages (MAP update, posterior covariance), greedy + exchange; "
                              "candidates landing with P >= 0.99", "earlier_contacts": int(len(table["axis"]))}
    else:
        pool = touch.pool(nominal, jig, n_candidates, seed, margin_m, campaign)
        t1 = time.perf_counter()
        if stages == 2:
            idx, p = staged.plan_first_stage(nominal, jig, pool, first_stage, sigma_m, campaign.approach_offset_m)
            extra = {"criterion": "one contact per face, then I-optimal under the prior error sizes, among the "
                                  "candidates likeliest "
                                  "to land (P >= 0.95, else the 3m likeliest)"}
        else:
            model = aw.TouchModel(nominal)
            terms = backlash_columns(model.parameter_names(), pool.dq, pool.travel) if backlash else None
            pl = plan(model, take(pool.table(), np.arange(pool.face.size)), m, extra=terms)
            idx = pl.selection.index
            p = staged.landing_probability(nominal.vector(), staged.prior_cov(nominal), jig, pool.take(idx),
                                           campaign.approach_offset_m)
            extra = {"criterion": "D-optimal: log det of the information matrix of the free parameters"
                                  + (" and every joint's backlash" if backlash else ""),
                     "logdet": pl.selection.logdet, "observability": pl.observability,
                     "free_parameters": int(pl.free.sum())}
            if backlash:  # the geometry's own, scaled as a plan without --backlash states its logdet
                from pipeline.plan.doptimal import logdet_info, scale

                J = model.jacobian(model.nominal(), take(pool.table(), np.arange(pool.face.size)))
                extra["logdet_geometry"] = logdet_info(scale(J[:, :, pl.free])[0], idx)
        doc = touch_document(aw.SYSTEM, nominal, jig, pool.take(idx), campaign, margin_m, 1, stages, idx)
    for row, pi in zip(doc["measurements"], p):
        row["landing_probability"] = float(pi)
    doc.update({"n_candidates": int(pool.face.size), "seed": seed, "selection_s": time.perf_counter() - t1,
                "elapsed_s_note": "selection_s excludes the candidates' inverse kinematics", **extra})
    if w := landing_warning(np.asarray(p, float)):
        doc["warnings"] = [w]
    return document_balance(doc)


LANDING_MIN = 0.5  # a contact predicted to land less often than this is named
LANDING_EXPECTED = 0.9  # warn when fewer than this share of the contacts is expected to land


def landing_warning(p: np.ndarray) -> str | None:
    """A warning when the plan's own landing probabilities (`staged.landing_probability`, under the
    model's uncertainty) predict a poor campaign: any contact below LANDING_MIN, or fewer than
    LANDING_EXPECTED of the contacts expected to land."""
    if p.size == 0:
        return None
    low = np.flatnonzero(p < LANDING_MIN)
    if not low.size and p.sum() >= LANDING_EXPECTED * p.size:
        return None
    return (f"this campaign is predicted to land poorly: {p.sum():.1f} of {p.size} contacts expected to touch their "
            f"face" + (f"; contacts {', '.join(str(int(i)) for i in low[:8])} below {LANDING_MIN:.0%}" if low.size else "")
            + " — widen the stand-off (--margin), plan a first stage (--stages 2), or calibrate roughly first")


def stages_so_far(run_dir) -> tuple:
    """(nominal arm, jig, contact table) of a run directory of an earlier stage."""
    from pathlib import Path

    from pipeline.errors import RobocalError
    from pipeline.ingest.tables import model_columns
    from pipeline.models.serial_arm import SerialArm
    from pipeline.recording.schemas import META_FIXTURE, META_ROBOT
    from pipeline.stages.ingest import read_measurements, recording_info

    info = recording_info(Path(run_dir))
    if info.get("system") != aw.SYSTEM:
        raise RobocalError(f"{run_dir}: is a {info.get('system')} run, not {aw.SYSTEM}")
    meta = info["metadata"]
    table = model_columns(read_measurements(Path(run_dir)))
    return SerialArm.from_dict(meta[META_ROBOT]), Jig.from_dict(meta[META_FIXTURE]), table
