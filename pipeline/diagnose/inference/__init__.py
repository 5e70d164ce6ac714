"""The inference of a diagnosis: which candidate terms the campaign can see and which ones the
data ask for, all linear algebra at the geometric solution.

- `projection`: orthonormal bases and projections;
- `gate`: detectability (absorbed fraction, minimum detectable size, confounding);
- `stepwise`: grouped-F forward selection with Holm's correction, look-alikes;
- `clustered`: pose-clustered inference (random-effects whitening, noise components, the
  physical cluster-error model); `sign_flips`: the cluster sign-flip checks;
- `screen`: the gate and the selection iterated with the noise model (feasible GLS);
- `forms`: the held-out choice among one term's functional forms;
- `augmented`: the measurement model augmented with the accepted terms, its parameters' covariance (shared
  errors, CR2) and intervals; `resampling`: grouped cross-validation on time blocks and the bootstrap;
- `refit`: the joint refit of geometry + accepted terms and each finding's evidence.
"""
