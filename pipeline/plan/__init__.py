"""Pose selection: D-optimal choice of M measurements out of N candidates."""
