"""Bringing measurements in: CSV tables (and ROS 2 bags) → self-contained robocal recordings."""
