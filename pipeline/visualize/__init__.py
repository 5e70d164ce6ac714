"""Rerun recordings of a run: the scene geometry (pure), per-system hooks, the .rrd writer."""
