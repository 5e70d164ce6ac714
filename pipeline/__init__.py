"""robocal: log-centric robot calibration (import package `pipeline`)."""

__version__ = "0.1.0"
