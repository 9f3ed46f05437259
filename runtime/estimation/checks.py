"""Argument checks the estimation classes share (ValueError naming the argument and its value)."""

from __future__ import annotations

import math

__all__ = ["check_positive", "check_range"]


def check_positive(**values: float) -> None:
    """Each keyword's value must be a finite number > 0."""
    for name, value in values.items():
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name}={value!r} must be a finite number > 0")


def check_range(name: str, lo: float, hi: float) -> None:
    """``(lo, hi)`` must be finite with 0 < lo < hi."""
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 < lo < hi):
        raise ValueError(f"{name}=({lo!r}, {hi!r}) must be finite with 0 < low < high")
