"""Identification: what the data can see (analysis), the solvers, `identify`, the answer
audit, the `Calibration` result with its summary, held-out validation and distances."""

from .fit import METHODS, identify

__all__ = ["METHODS", "identify"]
