"""Honest accuracy: priors, propagation to a workspace map, the verdict (issue 16)."""
