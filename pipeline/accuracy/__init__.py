"""Honest accuracy: priors, propagation to a workspace map, the verdict, the held-out check."""
