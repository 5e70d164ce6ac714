"""Apply a calibrated model to recordings it was not fitted to: errors per measurement and per recording."""
