"""Compensation: Cartesian targets → joint angles by the calibrated model's inverse kinematics,
and corrected targets for a controller that keeps its nominal model (pure numpy)."""
