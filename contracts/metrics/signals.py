"""Sampled-signal helpers shared by the metric modules: uniform tick grids, crossings, windows."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

TIME_EPS_S = 1e-9  # sample times are sums of float periods: a window edge must not split a tick


def to_float(x: float | np.floating) -> float:
    """A plain Python float (metric values are JSON-ready, never numpy scalars)."""
    return float(x)


def as_arrays(t_s: Sequence[float] | np.ndarray, *signals: Sequence[float] | np.ndarray):
    """``[t, *signals]`` as float arrays of one shape (a scalar signal is held constant).

    Raises
    ------
    ValueError
        ``t_s`` not 1-D with at least 2 samples, or a signal of another shape.
    """
    t = np.asarray(t_s, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise ValueError(f"t_s must be 1-D with at least 2 samples, got shape {t.shape}")
    out = [t]
    for s in signals:
        a = np.asarray(s, dtype=float)
        if a.ndim == 0:
            a = np.full_like(t, float(a))
        if a.shape != t.shape:
            raise ValueError(f"signal shape {a.shape} differs from t_s shape {t.shape}")
        out.append(a)
    return out


def period(t: np.ndarray) -> float:
    """The sample period Ts (s) of a uniform tick grid."""
    return float((t[-1] - t[0]) / (t.size - 1))


def first_crossing(t: np.ndarray, y: np.ndarray, level: float) -> float | None:
    """First time y reaches ``level`` from below, linearly interpolated; NaNs never cross."""
    above = np.flatnonzero(np.nan_to_num(y, nan=-np.inf) >= level)
    if above.size == 0:
        return None
    k = int(above[0])
    if k == 0 or not np.isfinite(y[k - 1]):
        return float(t[k])
    y0, y1 = y[k - 1], y[k]
    frac = 0.0 if y1 == y0 else (level - y0) / (y1 - y0)
    return float(t[k - 1] + frac * (t[k] - t[k - 1]))


def in_window(t: np.ndarray, start_s: float, end_s: float) -> np.ndarray:
    """Mask of the samples in [start_s, end_s) (s), tolerant of float sums of periods."""
    return (t >= start_s - TIME_EPS_S) & (t < end_s - TIME_EPS_S)


def percent(mask: np.ndarray) -> float:
    """Percentage of True samples in ``mask``."""
    return to_float(100.0 * np.count_nonzero(mask) / mask.size)
