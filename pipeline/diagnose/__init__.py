"""Diagnosis: find the physics the geometric model left out, name it, model it, show the fit improve.

Modules: `effects` (the library of compact parametric effects and their signatures), `table`
(measurement table with motion context from a recording), `select` (projection, gating,
grouped-F forward selection with Holm), `lack_of_fit` (smooth-basis tests that locate
unexplained structure), `confirm` (joint refit, grouped cross-validation, bootstrap),
`diagnose` (the pure pipeline), `stage` (files).
"""
