"""Disturbance events of a run: their windows, labels and per-event metrics.

Definitions: the package docstring (:mod:`pressor.contracts.metrics`) and docs/METRICS.md.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from pressor.contracts.metrics.names import CLINICAL_BAND_MMHG, EVENT_KINDS, EVENT_METRICS, Event
from pressor.contracts.metrics.signals import TIME_EPS_S, as_arrays, in_window, period, to_float


def event_windows(
    t_s: Sequence[float] | np.ndarray, events: Iterable[Event]
) -> list[tuple[str, float, float]]:
    """The events of a run with their windows, ``(kind, start_s, end_s)`` in start order.

    An event's window runs from its start to the next later start, the last one to the end of the
    run (the last sample time plus one period, rounded to the µs); events that start together share a window; events
    that start after the last sample are not in the run and are left out.

    Raises
    ------
    ValueError
        A kind outside :data:`EVENT_KINDS` or a non-finite start.
    """
    (t,) = as_arrays(t_s)
    run_end = round(float(t[-1]) + period(t), 6)  # µs: 300.0, not 300.00000000000006
    kept: list[tuple[str, float]] = []
    for kind, start in events:
        if kind not in EVENT_KINDS:
            raise ValueError(f"event kind {kind!r} must be one of {list(EVENT_KINDS)}")
        if not np.isfinite(start):
            raise ValueError(f"event {kind!r} start_s {start!r} must be finite")
        if start <= t[-1] + TIME_EPS_S:
            kept.append((kind, float(start)))
    kept.sort(key=lambda e: e[1])
    starts = [s for _, s in kept]
    out = []
    for kind, start in kept:
        later = [s for s in starts if s > start + TIME_EPS_S]
        out.append((kind, start, later[0] if later else run_end))
    return out


def event_labels(kinds: Sequence[str]) -> list[str]:
    """Stable names for a run's events: the kind, then ``kind_2``, ``kind_3`` for repeats."""
    seen: dict[str, int] = {}
    labels = []
    for kind in kinds:
        seen[kind] = seen.get(kind, 0) + 1
        labels.append(kind if seen[kind] == 1 else f"{kind}_{seen[kind]}")
    return labels


def _recovery_s(t: np.ndarray, e: np.ndarray, start_s: float, band: float) -> float | None:
    """Time (s) from ``start_s`` until e stays inside ±band to the last sample (docs/METRICS.md)."""
    valid = np.flatnonzero(np.isfinite(e))
    outside = valid[np.abs(e[valid]) > band]
    if outside.size == 0:
        return 0.0
    k = int(outside[-1])
    if k == int(valid[-1]):
        return None
    j = int(valid[valid > k][0])
    level = band if e[k] > 0 else -band
    frac = (e[k] - level) / (e[k] - e[j])  # e_j is inside the band, so this is in (0, 1]
    return to_float(t[k] + frac * (t[j] - t[k]) - start_s)


def disturbance_metrics(
    t_s: Sequence[float] | np.ndarray,
    map_mmhg: Sequence[float] | np.ndarray,
    target_mmhg: Sequence[float] | np.ndarray | float,
    events: Iterable[Event],
    band_mmhg: float = CLINICAL_BAND_MMHG,
) -> list[dict[str, str | float | None]]:
    """One record per disturbance event over its window (docs/METRICS.md).

    Parameters
    ----------
    t_s, map_mmhg, target_mmhg
        As for :func:`step_metrics`; NaN MAP samples are ignored.
    events
        ``(kind, start_s)`` pairs, kind in :data:`EVENT_KINDS`, in any order.
    band_mmhg
        The recovery band (mmHg) around the target.

    Returns
    -------
    list of dict
        In start order: ``kind``, ``start_s``, ``end_s`` (s), ``peak_deviation_mmhg`` (signed),
        ``recovery_s``, ``iae_mmhg_s``; the three numbers ``None`` for a window without a valid
        sample, ``recovery_s`` ``None`` when MAP is still outside the band at the window's end.
    """
    t, y, r = as_arrays(t_s, map_mmhg, target_mmhg)
    ts = period(t)
    records: list[dict[str, str | float | None]] = []
    for kind, start, end in event_windows(t, events):
        inside = in_window(t, start, end)
        tw, e = t[inside], (y - r)[inside]
        rec: dict[str, str | float | None] = {"kind": kind, "start_s": start, "end_s": end}
        rec.update(dict.fromkeys(EVENT_METRICS))
        valid = np.isfinite(e)
        if valid.any():
            k = int(np.nanargmax(np.abs(e)))
            rec["peak_deviation_mmhg"] = to_float(e[k])
            rec["recovery_s"] = _recovery_s(tw, e, start, band_mmhg)
            rec["iae_mmhg_s"] = to_float(np.sum(np.abs(e[valid])) * ts)
        records.append(rec)
    return records
