"""Measurements: the `Measurements` type, their simulation, and measurement files (CSV)."""
