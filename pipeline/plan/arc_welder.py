"""Candidate contacts of the arc-welder (seed 000) for pose planning.

A candidate is a contact: an approach pose over a jig face, reached by the nominal inverse
kinematics, and the search along the face normal until the wire touches.  They are made by
the campaign simulator itself run with the *nominal* model as truth and no noise — i.e. the
contacts the controller expects — so planning needs no measurement and no truth.
"""

from __future__ import annotations

import numpy as np

from pipeline.models.jig import Jig, stepped_block
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
