"""Fitting: lighting/albedo calibration (Eq. 14); scan and plate fits build on it."""
