"""Every metric of one run: step response, clinical band, Varvel errors, drug use, stability.

Definitions: the package docstring (:mod:`pressor.contracts.metrics`) and docs/METRICS.md.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from pressor.contracts.metrics.disturbance import disturbance_metrics
from pressor.contracts.metrics.harm import harm_metrics
from pressor.contracts.metrics.names import (
    CLINICAL_BAND_MMHG,
    NOISY_BAND_MMHG,
    STEP_METRICS,
    STEP_WINDOW_METRICS,
    Event,
)
from pressor.contracts.metrics.signals import as_arrays, percent, period, to_float
from pressor.contracts.metrics.step import step_band_mmhg, step_metrics, step_window_metrics


def stable_flag(
    map_true_mmhg: Sequence[float] | np.ndarray,
    target_mmhg: Sequence[float] | np.ndarray,
    band_mmhg: float,
) -> bool:
    """True when the run shows no divergence and no sustained oscillation (docs/METRICS.md)."""
    y = np.asarray(map_true_mmhg, dtype=float)
    r = np.broadcast_to(np.asarray(target_mmhg, dtype=float), y.shape)
    if not np.all(np.isfinite(y)):
        return False
    tail = (y - r)[int(0.75 * y.size) :]
    side = np.where(tail > band_mmhg, 1, np.where(tail < -band_mmhg, -1, 0))
    side = side[side != 0]
    swings = int(np.count_nonzero(np.diff(side) != 0)) if side.size > 1 else 0
    return swings < 2


def run_metrics(
    t_s: Sequence[float] | np.ndarray,
    map_mmhg: Sequence[float] | np.ndarray,
    target_mmhg: Sequence[float] | np.ndarray | float,
    rate_ml_h: Sequence[float] | np.ndarray,
    max_rate_ml_h: float,
    step_time_s: float | None = None,
    step_mmhg: float | None = None,
    noisy: bool = False,
    reachable: bool = True,
    map_true_mmhg: Sequence[float] | np.ndarray | None = None,
    events: Iterable[Event] | None = None,
) -> dict[str, Any]:
    """All metrics of one run, docs/METRICS.md (without the fault entries, which the runtime adds).

    Parameters
    ----------
    t_s, map_mmhg, target_mmhg
        As for :func:`step_metrics`; ``map_mmhg`` is the MAP the metrics judge (measured).
    rate_ml_h
        Delivered infusion rate (ml/h) at ``t_s`` (held over each tick).
    max_rate_ml_h
        Pump limit (ml/h), for ``time_at_limit_pct``.
    step_time_s, step_mmhg
        The target step (s, mmHg); ``None`` when the scenario has no step: the step metrics are
        then ``None`` and the other metrics count from the first sample.
    noisy
        The run has measurement noise (selects the 5 mmHg settling band).
    reachable
        The caller's reachability verdict for this patient and scenario.
    map_true_mmhg
        The true MAP for the ``stable`` flag; defaults to ``map_mmhg``.
    events
        The run's disturbance events, ``(kind, start_s)`` (:func:`disturbance_metrics`); ``[]``
        for a run without one; ``None`` when they are not known (the step-window metrics and
        ``disturbances`` are then ``None``).

    Returns
    -------
    dict
        Keys :data:`RUN_METRICS` + ``reachable`` + ``stable`` + ``disturbances``. The Varvel
        figures (``mdpe_pct``, ``mdape_pct``, ``wobble_pct``; %, and ``divergence_pct_per_h``,
        %/h) count the whole controlled period: every valid sample from the target step on (from
        the first sample without a step), the rise included, not only the time after the target
        is first reached. The harm metrics (:mod:`pressor.contracts.metrics.harm`) judge ``map_mmhg``.
    """
    t, y, r, u = as_arrays(t_s, map_mmhg, target_mmhg, rate_ml_h)
    ts = period(t)
    has_step = step_time_s is not None and step_mmhg is not None and step_mmhg != 0.0
    if has_step:
        out: dict[str, Any] = dict(
            step_metrics(t, y, r, float(step_time_s), float(step_mmhg), noisy=noisy)
        )
        t0 = float(step_time_s)
    else:
        out = dict.fromkeys(STEP_METRICS)
        t0 = float(t[0])
        e_all = np.abs(y - r)
        ok = np.isfinite(e_all)
        n_tail = max(1, int(round(0.1 * t.size)))
        tail = e_all[-n_tail:][np.isfinite(e_all[-n_tail:])]
        out["steady_state_dev_mmhg"] = to_float(tail.mean()) if tail.size else None
        out["iae_mmhg_s"] = to_float(np.sum(e_all[ok]) * ts) if ok.any() else None
    after = t >= t0 - 1e-9
    e = (y - r)[after]
    ra = r[after]
    valid = np.isfinite(e)
    arrived = np.flatnonzero(valid & (np.abs(e) <= CLINICAL_BAND_MMHG))
    if arrived.size:
        window = e[arrived[0] :]
        window = window[np.isfinite(window)]
        out["time_in_band_pct"] = percent(np.abs(window) <= CLINICAL_BAND_MMHG)
        out["time_below_pct"] = percent(window < -CLINICAL_BAND_MMHG)
    else:
        out["time_in_band_pct"] = None
        out["time_below_pct"] = None
    if valid.any():
        pe = 100.0 * e[valid] / ra[valid]
        mdpe = float(np.median(pe))
        out["mdpe_pct"] = to_float(mdpe)
        out["mdape_pct"] = to_float(np.median(np.abs(pe)))
        out["wobble_pct"] = to_float(np.median(np.abs(pe - mdpe)))
    else:
        out["mdpe_pct"] = out["mdape_pct"] = out["wobble_pct"] = None
    out["drug_total_ml"] = to_float(np.sum(u) * ts / 3600.0)
    out["max_rate_ml_h"] = to_float(np.max(u))
    out["time_at_limit_pct"] = percent(u >= max_rate_ml_h * (1.0 - 1e-6))
    out.update(dict.fromkeys(STEP_WINDOW_METRICS))
    disturbances = None
    first: float | None = None  # the step window's end (s); None when the events are not known
    if events is not None:
        disturbances = disturbance_metrics(t, y, r, events)
        first = float(disturbances[0]["start_s"]) if disturbances else math.inf  # type: ignore[arg-type]
        if has_step:
            out.update(
                step_window_metrics(t, y, r, float(step_time_s), float(step_mmhg), first, noisy)
            )
    out.update(harm_metrics(t, y, r, t0, float(step_mmhg) if has_step else None, first))
    band = (
        step_band_mmhg(float(step_mmhg), noisy)
        if has_step
        else (NOISY_BAND_MMHG if noisy else CLINICAL_BAND_MMHG)
    )
    truth = y if map_true_mmhg is None else np.asarray(map_true_mmhg, dtype=float)
    out["reachable"] = bool(reachable)
    out["stable"] = stable_flag(truth, r, max(band, 1.0))
    out["disturbances"] = disturbances
    return out
