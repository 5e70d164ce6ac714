"""Rerun hook of the `delta-tracker` system (looked up by system name); see `pipeline.visualize.delta`."""

from pipeline.visualize.delta import log_system

__all__ = ["log_system"]
