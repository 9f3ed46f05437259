"""What harms the patient: hypertension the device causes, time to the target, divergence.

Definitions: the package docstring (:mod:`pressor.contracts.metrics`) and docs/METRICS.md. Every function
takes the run's samples on a uniform tick grid (``t_s`` in s, MAP and target in mmHg) and counts
from ``start_s`` (s, the target step, or the first sample without one). Non-finite MAP samples are
ignored: they neither count nor break a continuous stretch (a monitor dropout inside a hypertensive
episode must not reset its clock).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pressor.contracts.metrics.names import (
    CLINICAL_BAND_MMHG,
    HARM_METRICS,
    OVER_TARGET_MARGIN_MMHG,
)
from pressor.contracts.metrics.signals import TIME_EPS_S, as_arrays, period, to_float

_S_PER_H = 3600.0


def _valid_after(
    t_s: Sequence[float] | np.ndarray,
    map_mmhg: Sequence[float] | np.ndarray,
    target_mmhg: Sequence[float] | np.ndarray | float,
    start_s: float,
    end_s: float = np.inf,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """``(t, e, target, Ts)`` of the valid samples in [start_s, end_s); e = MAP − target (mmHg)."""
    t, y, r = as_arrays(t_s, map_mmhg, target_mmhg)
    keep = (t >= start_s - TIME_EPS_S) & (t < end_s - TIME_EPS_S) & np.isfinite(y)
    return t[keep], (y - r)[keep], r[keep], period(t)


def longest_above_s(
    t_s: Sequence[float] | np.ndarray,
    map_mmhg: Sequence[float] | np.ndarray,
    target_mmhg: Sequence[float] | np.ndarray | float,
    start_s: float,
    margin_mmhg: float = OVER_TARGET_MARGIN_MMHG,
) -> float | None:
    """The longest continuous time (s) MAP stays above target + ``margin_mmhg`` from ``start_s``.

    A stretch is a run of consecutive valid samples with e > ``margin_mmhg`` (mmHg, strictly); its
    duration is its sample count × Ts (the rectangle rule of every time sum here). 0 when MAP is
    never above; ``None`` without a valid sample.
    """
    _, e, _, ts = _valid_after(t_s, map_mmhg, target_mmhg, start_s)
    if e.size == 0:
        return None
    above = np.concatenate(([0], (e > margin_mmhg).astype(np.int8), [0]))
    edges = np.flatnonzero(np.diff(above))  # starts at even indices, ends at odd ones
    if edges.size == 0:
        return 0.0
    return to_float(int(np.max(edges[1::2] - edges[0::2])) * ts)


def time_to_band_s(
    t_s: Sequence[float] | np.ndarray,
    map_mmhg: Sequence[float] | np.ndarray,
    target_mmhg: Sequence[float] | np.ndarray | float,
    start_s: float,
    band_mmhg: float = CLINICAL_BAND_MMHG,
) -> float | None:
    """Time (s) from ``start_s`` to the first valid sample with |e| ≤ ``band_mmhg`` (mmHg).

    The same arrival ``time_in_band_pct`` counts from (docs/METRICS.md, "after arrival"); 0 when
    MAP is already inside at ``start_s``; ``None`` when it never gets there.
    """
    t, e, _, _ = _valid_after(t_s, map_mmhg, target_mmhg, start_s)
    inside = np.flatnonzero(np.abs(e) <= band_mmhg)
    return None if inside.size == 0 else to_float(t[inside[0]] - start_s)


def divergence_pct_per_h(
    t_s: Sequence[float] | np.ndarray,
    map_mmhg: Sequence[float] | np.ndarray,
    target_mmhg: Sequence[float] | np.ndarray | float,
    start_s: float,
) -> float | None:
    """Varvel's divergence (%/h): the least-squares slope of |PE_k| against time from ``start_s``.

    PE_k = 100·e_k/target_k (%), t in hours. Negative when the error shrinks over the run (a step
    response that settles), positive when it grows (a loop drifting away or starting to
    oscillate). ``None`` with fewer than two valid samples.
    """
    t, e, r, _ = _valid_after(t_s, map_mmhg, target_mmhg, start_s)
    if t.size < 2:
        return None
    hours = (t - t[0]) / _S_PER_H
    ape = np.abs(100.0 * e / r)
    dt = hours - hours.mean()
    return to_float(np.dot(dt, ape - ape.mean()) / np.dot(dt, dt))


def step_overshoot_mmhg(
    t_s: Sequence[float] | np.ndarray,
    map_mmhg: Sequence[float] | np.ndarray,
    target_mmhg: Sequence[float] | np.ndarray | float,
    step_time_s: float,
    step_mmhg: float,
    end_s: float,
) -> float | None:
    """The step overshoot in mmHg: max(0, largest sign(Δ)·e) over [``step_time_s``, ``end_s``).

    ``step_overshoot_pct`` × |Δ| / 100 without the round trip through %: how far past the target
    (mmHg) the step drove MAP before the first disturbance event. ``None`` under the same rule as
    ``step_overshoot_pct``: fewer than two samples in the window, or no valid one.
    """
    t, y, _ = as_arrays(t_s, map_mmhg, target_mmhg)
    n_window = np.count_nonzero((t >= step_time_s - TIME_EPS_S) & (t < end_s - TIME_EPS_S))
    _, e, _, _ = _valid_after(t_s, map_mmhg, target_mmhg, step_time_s, end_s)
    if n_window < 2 or e.size == 0:
        return None
    sign = 1.0 if step_mmhg > 0 else -1.0
    return to_float(max(0.0, float(np.max(sign * e))))


def harm_metrics(
    t_s: Sequence[float] | np.ndarray,
    map_mmhg: Sequence[float] | np.ndarray,
    target_mmhg: Sequence[float] | np.ndarray | float,
    start_s: float,
    step_mmhg: float | None = None,
    step_end_s: float | None = None,
) -> dict[str, float | None]:
    """:data:`pressor.contracts.metrics.names.HARM_METRICS` of one run.

    Parameters
    ----------
    t_s, map_mmhg, target_mmhg
        Sample times (s, uniform), MAP and target (mmHg).
    start_s
        Where the run's control period starts (s): the target step, or the first sample.
    step_mmhg
        Δ (mmHg) of the target step at ``start_s``; ``None`` without a step
        (``step_overshoot_mmhg`` is then ``None``).
    step_end_s
        End of the step window (s): the first disturbance event's start, ``inf`` without one;
        ``None`` when the events are not known (``step_overshoot_mmhg`` is then ``None``).

    Returns
    -------
    dict
        ``step_overshoot_mmhg`` (mmHg), ``longest_above_10_mmhg_s`` (s), ``time_to_band_s`` (s),
        ``divergence_pct_per_h`` (%/h).
    """
    out: dict[str, float | None] = dict.fromkeys(HARM_METRICS)
    if step_mmhg is not None and step_mmhg != 0.0 and step_end_s is not None:
        out["step_overshoot_mmhg"] = step_overshoot_mmhg(
            t_s, map_mmhg, target_mmhg, start_s, step_mmhg, step_end_s
        )
    out["longest_above_10_mmhg_s"] = longest_above_s(t_s, map_mmhg, target_mmhg, start_s)
    out["time_to_band_s"] = time_to_band_s(t_s, map_mmhg, target_mmhg, start_s)
    out["divergence_pct_per_h"] = divergence_pct_per_h(t_s, map_mmhg, target_mmhg, start_s)
    return out
