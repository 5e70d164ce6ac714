"""Staged planning: the predicted landing probability against Monte-Carlo truths drawn from the
prior, and the MAP update between stages."""

from __future__ import annotations

import numpy as np

from pipeline.models import serial_arm
from pipeline.models.jig import stepped_block
from pipeline.plan import staged, touch
from pipeline.simulate.campaign_run import landing
from pipeline.systems import arc_welder as aw


def test_landing_probability_matches_monte_carlo_truths_from_the_prior():
    nominal, jig = aw.nominal_arm(), stepped_block()
    pool = touch.pool(nominal, jig, 80, seed=5, margin_m=0.01)
    cov = staged.prior_cov(nominal)
    p = staged.landing_probability(nominal.vector(), cov, jig, pool, 0.04)
    rng = np.random.default_rng(0)
    sd = np.sqrt(np.diag(cov))
    hits = np.mean([landing(nominal.vector() + rng.normal(0, 1, sd.size) * sd, jig, pool.face, pool.q_approach,
                            pool.dq, 0.09)[0] for _ in range(150)], axis=0)
    assert abs(p.mean() - hits.mean()) < 0.1  # linearised: measured 0.57 vs 0.52
    assert np.corrcoef(p, hits)[0, 1] > 0.8  # and it ranks the candidates


def test_map_update_after_a_first_stage_predicts_the_true_robot_to_millimetres():
    nominal, truth, jig = aw.nominal_arm(), aw.reference_truth(), stepped_block()
    pool = touch.pool(nominal, jig, 300, seed=1, margin_m=0.01)
    idx, _ = staged.plan_first_stage(nominal, jig, pool, 15)
    sel = pool.take(idx)
    hit, _, s = landing(truth.vector(), jig, sel.face, sel.q_approach, sel.dq, 0.09)
    q = sel.q_approach[hit] + s[hit, None] * sel.dq[hit]
    p = serial_arm.tip_position(truth.vector(), q)
    table = {"joint_positions": q, "axis": sel.axis[hit], "coordinate": p[np.arange(hit.sum()), sel.axis[hit]]}
    x, cov = staged.map_fit(aw.TouchModel(nominal), table, staged.prior_cov(nominal), 5e-5)
    test = touch.pool(nominal, jig, 100, seed=9, margin_m=0.0).q_contact
    err = lambda xx: np.sqrt(np.mean(np.sum((serial_arm.tip_position(truth.vector(), test)  # noqa: E731
                                             - serial_arm.tip_position(xx, test)) ** 2, axis=1)))
    assert hit.sum() >= 12
    assert err(x) < 0.5 * err(nominal.vector())  # 15 contacts halve the error at least (measured ~5-10 mm vs 35 mm)
    assert np.all(np.linalg.eigvalsh(cov[np.ix_(np.diag(cov) > 0, np.diag(cov) > 0)]) > 0)
