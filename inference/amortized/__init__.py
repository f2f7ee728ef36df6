"""Amortized calibration (module docs in each file)."""
