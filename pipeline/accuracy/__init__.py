"""Honest accuracy: priors, propagation to a workspace map, the verdict (pass / insufficient / fail)."""
