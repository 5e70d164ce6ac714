"""Observability of a calibration campaign: singular values, indices O1..O5, correlations."""
