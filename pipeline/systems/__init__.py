"""The reference calibration systems: each pairs a robot model with a measurement model."""
