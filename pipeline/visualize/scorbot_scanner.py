"""Run-level hook name for the scanner: `pipeline.visualize.scanner.log_system`."""

from pipeline.visualize.scanner import log_system, stripes_of  # noqa: F401
