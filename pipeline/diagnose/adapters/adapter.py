"""What is system-specific in a diagnosis (`Adapter`): the candidate terms, their signatures,
the lack-of-fit variables, the time axis and the cluster/noise models of one kind of campaign."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from pipeline.diagnose.library.term import Effect


@dataclass(frozen=True)
class Adapter:
    """What is system-specific in a diagnosis (everything else is shared).

    - `library`: the candidate effects;
    - `signatures(x, data, effects)`: list of (n, residual_dim, k_e) residual change per unit
      parameter of each effect at geometric parameters x (m/unit);
    - `variables(x)`: lack-of-fit `Variable`s whose rows are the flattened residual rows
      (measurement-major, n·residual_dim);
    - `time_s` (n,): time since start (s), for cross-validation blocks;
    - `located(effect)`: (label, values (n,)) — the variable an effect acts through, for the
      added-variable plots (None: the measurement index);
    - `cluster` (n,): the cluster (pose) of each measurement when several measurements share
      one pose's error (None: every measurement is its own cluster), and `cluster_basis(x)`
      (n, residual_dim, p): how a pose's error reaches each residual (None: a shift per
      residual axis) — the tests are then made under the random-effects model of
      `inference.clustered.cluster_whitener` (pose-clustered inference, docs/guide/diagnose.md);
    - `cluster_model(x)`: (B (n, residual_dim, p), column groups) — a physical model of the cluster
      error (B_g e_g, e_g ~ N(0, diag θ), θ shared within each group, estimated from the data):
      the lack-of-fit test then whitens by it and takes its p-values from a parametric bootstrap
      under it (`physical_reference`) instead of the sign flips;
    - `shared_error`: (Z (n·residual_dim, g) group membership, τ² m²) — an error shared by the
      rows of a group with a variance known a priori (a jig face's machining error within the
      jig's tolerance); the refit's parameter std then use `augmented.shared_error_covariance`.
    """

    library: list[Effect]
    signatures: Callable[[np.ndarray, object, tuple], list[np.ndarray]]
    variables: Callable[[np.ndarray], list]
    time_s: np.ndarray
    located: Callable[[Effect], tuple[str, np.ndarray] | None] = lambda e: None
    cluster: np.ndarray | None = None
    cluster_basis: Callable[[np.ndarray], np.ndarray] | None = None
    noise_shape: Callable[[np.ndarray], np.ndarray] | None = None
    cluster_model: Callable[[np.ndarray], tuple[np.ndarray, list[np.ndarray]]] | None = None
    shared_error: tuple[np.ndarray, float] | None = None
    held: tuple[str, ...] = ()  # weak-gauge parameters the geometric baseline holds at the model's nominal
    # refit(effects): the joint refit's exact model of those effects when some are not additive
    # enough (`augmented.AugmentedModel.exact`), or None (the additive model)
    refit: Callable[[tuple], Callable | None] | None = None
    # floor_variance(x) (n·residual_dim,) m²: the noise floor the campaign supports (`verdict.checks.floor_check`)
    floor_variance: Callable[[np.ndarray], np.ndarray] | None = None
    # advice(variable): what to do about structure located along a variable when the campaign knows
    # better than the variable's name (a joint reading that tracks the joint's gravity load), or None
    advice: Callable[[str], str | None] | None = None
    # the joint refit holds the effects' signatures at the geometric solution (`augmented.AugmentedModel.frozen`)
    # instead of re-evaluating them at every trial point: for signatures that cost a model evaluation per joint
    # (the URDF adapter's central differences); the change it neglects is second order (effect × geometry move)
    frozen_refit: bool = False
