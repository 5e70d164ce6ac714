"""The inference of a diagnosis: which candidate terms the campaign can see and which ones the
data ask for, all linear algebra at the geometric solution.

- `projection`: orthonormal bases and projections;
- `gate`: detectability (absorbed fraction, minimum detectable size, confounding);
- `stepwise`: grouped-F forward selection with Holm's correction, look-alikes;
- `clustered`: pose-clustered inference (random-effects whitening, noise components, the
  physical cluster-error model); `sign_flips`: the cluster sign-flip checks;
- `screen`: the gate and the selection iterated with the noise model (feasible GLS);
- `forms`: the held-out choice among one term's functional forms;
- `confirm`: the augmented measurement model, grouped cross-validation, bootstrap, CR2 intervals;
- `refit`: the joint refit of geometry + accepted terms and each finding's evidence.
"""
