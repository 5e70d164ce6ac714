"""Which candidate effects the campaign can see, and which ones the data ask for.

Linear algebra at the geometric solution (Frisch–Waugh–Lovell): with Q an orthonormal basis
of the free geometric Jacobian columns, a candidate's *projected signature* S⊥ = (I − QQᵀ)S
is what of it the geometry cannot absorb, and the residual r is already ⊥ Q at the optimum.

- `gate`: absorbed fraction 1 − ‖S⊥‖²/‖S‖², minimum detectable size along the candidate's
  weakest direction, (z₁₋α/(2m) + z₀.₈)·σ/s_min(S⊥) (+ its immaterial tolerance), and
  confounding with other candidates; a candidate whose detectable size is beyond what is
  physically plausible is `not_identifiable`.
- `sigma_given`: the residual σ after the effects accepted so far — the gate's σ once something
  is accepted (the geometry-only σ carries the unmodelled effects and inflates every MDS).
- `forward_select`: stepwise selection by grouped F tests under Holm's step-down thresholds
  α/(m − j), m the number of testable candidates:
  1. greedy forward pass: add the block with the smallest p given the geometry and the blocks
     already accepted while it passes α/(m − j) (j accepted so far; exact ties — blocks
     interchangeable given the accepted set — to the block that alone explains most).  Nothing accepted → stop:
     the refinement never runs on data where the greedy pass finds nothing, so it cannot raise the
     family error of a clean campaign;
  2. backward elimination: test every accepted block given all the others (last-in grouped F);
     while Holm's step-down over these p-values does not reject them all, drop the least
     significant block;
  3. forward additions again (single blocks, same thresholds), then a pair addition: the pair of
     blocks whose joint grouped F given the accepted set is smallest, added when it passes
     α/(m − j) divided by the number of pairs tried (Bonferroni over the search);
  4. repeat 2–3 until the set no longer changes; the blocks reported are those of the final
     backward step, each with its F given the others and Holm-adjusted p.
  A pair whose sum a third candidate imitates (c ≈ a + b after projection) is the case this is
  for: the greedy pass takes c and, given c, neither a nor b alone is significant; the pair {a, b}
  is, and then c is no longer significant given {a, b}.  Conversely, when c alone is the truth and
  lies in span(a, b), {a, b} adds only noise directions and parsimony keeps c.  Everything after
  the set-up is algebra on the K×K Gram matrix of the unit-scaled candidate columns (K = Σk_c):
  fits of any set and the tests of every block or pair against it, no refits.

The code lives in one module per concept (this module re-exports it): `projection` (orthonormal
bases), `gate` (detectability), `stepwise` (selection, look-alikes), `sign_flips` (the cluster sign-flip checks), `clustered`
(pose-clustered inference and the physical cluster-error model).
"""

from __future__ import annotations

from pipeline.diagnose.projection import (  # noqa: F401
    orthonormal, project_out)
from pipeline.diagnose.gate import (  # noqa: F401
    POWER_Z, RANK_REL, CONFOUND, Gate, _unit, _share, _explained, absorbing_parameters, _gate_parts, gate, sigma_given)
from pipeline.diagnose.stepwise import (  # noqa: F401
    Step, _batches, _single_batches, _pair_batches, _Design, _conditional, forward_select, _holm_steps, conditional_steps, look_alikes)
from pipeline.diagnose.sign_flips import (  # noqa: F401
    wild_cluster_p, cluster_sign_flip_p)
from pipeline.diagnose.clustered import (  # noqa: F401
    Whitener, NoiseModel, noise_components, _covariance_and_scale, measurement_covariance, measurement_whitener, cluster_whitener, PhysicalModel, _cluster_gram, _block_columns, physical_components, physical_whitener,
    sign_flip_elimination)
