"""Cameras: projection models, calibration targets and their detection in images."""
