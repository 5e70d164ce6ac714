"""Honest accuracy: priors, propagation to a workspace map, the verdict (pass / warn / insufficient / fail), the held-out check."""
