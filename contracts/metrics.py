"""Clinical performance metrics of a MAP control run (DESIGN.md §3), pure numpy.

``docs/METRICS.md`` defines every metric name, window, band, unit and null rule; this docstring
is the short form.

Every function takes sampled signals on a uniform tick grid (``t_s`` in s, MAP and target in mmHg,
rates in ml/h) and returns plain Python floats / bools / ``None`` under exactly the §3 JSON names.
A metric that does not apply (no target step, never reached, never settled, no valid sample) is
``None``, never a made-up number. Non-finite MAP samples (a faulted monitor reports NaN) are
ignored by every MAP metric; time-based percentages count only valid samples.

Definitions (a target step of size Δ mmHg at ``t0``; e = MAP − target):

``overshoot_pct``
    100·max(0, max_{t≥t0} e(t)) / Δ.
``rise_time_s``
    t90 − t10, the first times after t0 that MAP − (target − Δ) reaches 10 % and 90 % of Δ
    (linear interpolation between samples). ``None`` if 90 % is never reached.
``settling_time_s``
    The last sample time after t0 with |e| > band, minus t0 (0 if never outside the band); band =
    2 % of Δ for noise-free runs and 5 mmHg for noisy runs. ``None`` if the last valid sample is
    still outside the band (never settled).
``steady_state_dev_mmhg``
    Mean |e| over the final 10 % of the run (at least one sample).
``iae_mmhg_s``
    Σ |e_k|·Ts over valid samples from t0 to the end (rectangle rule on the tick grid).
``time_in_band_pct`` / ``time_below_pct``
    After settling — taken as the first time after t0 that |e| ≤ 5 mmHg, i.e. once the response
    has arrived (with a 5 mmHg band the §3 settling time would make the in-band share 100 % by
    construction) — the % of valid samples with |e| ≤ 5 mmHg, resp. with e < −5 mmHg. ``None``
    if MAP never comes within 5 mmHg of the target.
``mdpe_pct`` / ``mdape_pct`` / ``wobble_pct`` (Varvel et al. 1992)
    PE_k = 100·e_k/target_k over valid samples from t0 on; MDPE = median PE, MDAPE = median |PE|,
    wobble = median |PE_k − MDPE|.
``drug_total_ml``
    Σ rate_k·Ts / 3600 (rate = delivered pump rate, ml/h).
``max_rate_ml_h``
    max rate_k.
``time_at_limit_pct``
    % of ticks with rate ≥ max_rate − 1e-6·max_rate.
``stable``
    All true MAP samples finite and no sustained oscillation: in the final quarter of the run the
    error does not swing from above +band to below −band (or back) twice or more.
``reachable``
    Supplied by the caller (it needs the patient model): the target's required ΔMAP is within what
    the pump's maximum rate can produce at the patient's steady-state sensitivity.

The names above keep their meaning whatever the scenario: they judge the whole run after the step,
so on a scenario with disturbances ``overshoot_pct`` includes any disturbance's excursion above the
target and ``settling_time_s`` the last excursion out of the band, whatever caused it. Tracking and
disturbance rejection are told apart by the caller's list of disturbance events, ``(kind,
start_s)`` pairs (:data:`EVENT_KINDS`; a continuous sinusoid is background, not an event):

``step_overshoot_pct`` / ``step_rise_time_s`` / ``step_settling_time_s`` / ``step_iae_mmhg_s``
    ``overshoot_pct`` / ``rise_time_s`` / ``settling_time_s`` / ``iae_mmhg_s`` over the step window
    [t0, first event start) — the whole run when there is no event; ``None`` when the first event
    starts at or before t0, and all four ``None`` when the events are not known.
``disturbances``
    One record per event, in start order, over its event window [start, next later start) — the
    last one to the end of the run: ``kind``, ``start_s``, ``end_s`` (the window's end, s),
    ``peak_deviation_mmhg`` (e at the sample of largest |e|, sign kept: negative for a dip),
    ``recovery_s`` (from the start to the time MAP is back inside ±5 mmHg of the target for the
    rest of the window, interpolated linearly between the last valid sample outside the band and
    the next valid one; 0 if it never left the band, ``None`` if the window's last valid sample is
    outside) and ``iae_mmhg_s`` (Σ |e_k|·Ts over the window's valid samples). Events that start
    after the last sample are not in the run and get no record; a window without a valid sample
    gives ``None`` for the three numbers. ``None`` (not a list) when the events are not known.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

NOISY_BAND_MMHG = 5.0
NOISE_FREE_BAND_FRACTION = 0.02
CLINICAL_BAND_MMHG = 5.0

STEP_METRICS = (
    "overshoot_pct",
    "rise_time_s",
    "settling_time_s",
    "steady_state_dev_mmhg",
    "iae_mmhg_s",
)
STEP_WINDOW_METRICS = (
    "step_overshoot_pct",
    "step_rise_time_s",
    "step_settling_time_s",
    "step_iae_mmhg_s",
)
"""The step metrics over the window before the first disturbance event."""
RUN_METRICS = (
    STEP_METRICS
    + (
        "time_in_band_pct",
        "time_below_pct",
        "mdpe_pct",
        "mdape_pct",
        "wobble_pct",
        "drug_total_ml",
        "max_rate_ml_h",
        "time_at_limit_pct",
    )
    + STEP_WINDOW_METRICS
)
EVENT_KINDS = ("hemorrhage", "bolus")
"""Disturbance kinds that are events with a start; a sinusoid is continuous background."""
EVENT_METRICS = ("peak_deviation_mmhg", "recovery_s", "iae_mmhg_s")
"""The numbers of one disturbance record (besides ``kind``, ``start_s``, ``end_s``)."""
_TIME_EPS_S = 1e-9  # sample times are sums of float periods: a window edge must not split a tick

Event = tuple[str, float]
"""A disturbance event: ``(kind, start_s)``, kind in :data:`EVENT_KINDS`, start in s."""


def _f(x: float | np.floating) -> float:
    return float(x)


def _as_arrays(t_s: Sequence[float] | np.ndarray, *signals: Sequence[float] | np.ndarray):
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


def _period(t: np.ndarray) -> float:
    return float((t[-1] - t[0]) / (t.size - 1))


def _first_crossing(t: np.ndarray, y: np.ndarray, level: float) -> float | None:
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


def step_band_mmhg(step_mmhg: float, noisy: bool) -> float:
    """Settling band (mmHg): 2 % of |Δ| for noise-free runs, 5 mmHg for noisy runs."""
    return NOISY_BAND_MMHG if noisy else NOISE_FREE_BAND_FRACTION * abs(step_mmhg)


def step_metrics(
    t_s: Sequence[float] | np.ndarray,
    map_mmhg: Sequence[float] | np.ndarray,
    target_mmhg: Sequence[float] | np.ndarray | float,
    step_time_s: float,
    step_mmhg: float,
    noisy: bool = False,
    band_mmhg: float | None = None,
) -> dict[str, float | None]:
    """Step-response metrics of one run (module docstring gives the definitions).

    Parameters
    ----------
    t_s
        Sample times (s), uniform.
    map_mmhg
        MAP (mmHg) at ``t_s``; NaN samples are ignored.
    target_mmhg
        Target (mmHg) at ``t_s`` (or one constant).
    step_time_s
        t0 (s), the time of the target step.
    step_mmhg
        Δ (mmHg), the size of the step (non-zero; a negative step measures a fall).
    noisy
        Selects the settling band: 5 mmHg if True, else 2 % of |Δ|.
    band_mmhg
        Overrides the settling band (mmHg).

    Returns
    -------
    dict
        ``overshoot_pct``, ``rise_time_s``, ``settling_time_s``, ``steady_state_dev_mmhg``,
        ``iae_mmhg_s``; ``None`` where a metric does not apply.
    """
    t, y, r = _as_arrays(t_s, map_mmhg, target_mmhg)
    if step_mmhg == 0.0 or not np.isfinite(step_mmhg):
        raise ValueError(f"step_mmhg must be finite and non-zero, got {step_mmhg!r}")
    band = step_band_mmhg(step_mmhg, noisy) if band_mmhg is None else float(band_mmhg)
    ts = _period(t)
    after = t >= step_time_s - 1e-9
    ta, ya, ra = t[after], y[after], r[after]
    valid = np.isfinite(ya)
    out: dict[str, float | None] = dict.fromkeys(STEP_METRICS)
    if not valid.any():
        return out
    sign = 1.0 if step_mmhg > 0 else -1.0
    # Error in the direction of the step: positive means past the target.
    e_dir = sign * (ya - ra)
    out["overshoot_pct"] = _f(100.0 * max(0.0, float(np.nanmax(e_dir))) / abs(step_mmhg))
    progress = sign * (ya - (ra - step_mmhg))  # 0 at the old level, |Δ| at the target
    t10 = _first_crossing(ta, progress, 0.1 * abs(step_mmhg))
    t90 = _first_crossing(ta, progress, 0.9 * abs(step_mmhg))
    out["rise_time_s"] = None if t10 is None or t90 is None else _f(t90 - t10)
    err = np.abs(ya - ra)
    outside = np.flatnonzero(valid & (err > band))
    last_valid = int(np.flatnonzero(valid)[-1])
    if outside.size == 0:
        out["settling_time_s"] = 0.0
    elif outside[-1] == last_valid:
        out["settling_time_s"] = None
    else:
        out["settling_time_s"] = _f(ta[outside[-1]] - step_time_s)
    n_tail = max(1, int(round(0.1 * t.size)))
    tail = np.abs(y[-n_tail:] - r[-n_tail:])
    tail = tail[np.isfinite(tail)]
    out["steady_state_dev_mmhg"] = _f(tail.mean()) if tail.size else None
    out["iae_mmhg_s"] = _f(np.sum(err[valid]) * ts)
    return out


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
    (t,) = _as_arrays(t_s)
    run_end = round(float(t[-1]) + _period(t), 6)  # µs: 300.0, not 300.00000000000006
    kept: list[tuple[str, float]] = []
    for kind, start in events:
        if kind not in EVENT_KINDS:
            raise ValueError(f"event kind {kind!r} must be one of {list(EVENT_KINDS)}")
        if not np.isfinite(start):
            raise ValueError(f"event {kind!r} start_s {start!r} must be finite")
        if start <= t[-1] + _TIME_EPS_S:
            kept.append((kind, float(start)))
    kept.sort(key=lambda e: e[1])
    starts = [s for _, s in kept]
    out = []
    for kind, start in kept:
        later = [s for s in starts if s > start + _TIME_EPS_S]
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


def _in_window(t: np.ndarray, start_s: float, end_s: float) -> np.ndarray:
    return (t >= start_s - _TIME_EPS_S) & (t < end_s - _TIME_EPS_S)


def step_window_metrics(
    t_s: Sequence[float] | np.ndarray,
    map_mmhg: Sequence[float] | np.ndarray,
    target_mmhg: Sequence[float] | np.ndarray | float,
    step_time_s: float,
    step_mmhg: float,
    end_s: float,
    noisy: bool = False,
) -> dict[str, float | None]:
    """``step_overshoot_pct``, ``step_rise_time_s``, ``step_settling_time_s``, ``step_iae_mmhg_s``.

    :func:`step_metrics` over the samples in [``step_time_s``, ``end_s``) (s), normally ``end_s``
    = the first disturbance event's start. All ``None`` when that window holds fewer than two
    samples (an event at or before the step leaves no clean step to judge).
    """
    t, y, r = _as_arrays(t_s, map_mmhg, target_mmhg)
    out: dict[str, float | None] = dict.fromkeys(STEP_WINDOW_METRICS)
    keep = t < end_s - _TIME_EPS_S
    if np.count_nonzero(keep & (t >= step_time_s - _TIME_EPS_S)) < 2:
        return out
    m = step_metrics(t[keep], y[keep], r[keep], step_time_s, step_mmhg, noisy=noisy)
    for name in STEP_WINDOW_METRICS:
        out[name] = m[name.removeprefix("step_")]
    return out


def _recovery_s(t: np.ndarray, e: np.ndarray, start_s: float, band: float) -> float | None:
    """Time (s) from ``start_s`` until e stays inside ±band to the last sample (module docstring)."""
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
    return _f(t[k] + frac * (t[j] - t[k]) - start_s)


def disturbance_metrics(
    t_s: Sequence[float] | np.ndarray,
    map_mmhg: Sequence[float] | np.ndarray,
    target_mmhg: Sequence[float] | np.ndarray | float,
    events: Iterable[Event],
    band_mmhg: float = CLINICAL_BAND_MMHG,
) -> list[dict[str, str | float | None]]:
    """One record per disturbance event over its window (module docstring, docs/METRICS.md).

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
    t, y, r = _as_arrays(t_s, map_mmhg, target_mmhg)
    ts = _period(t)
    records: list[dict[str, str | float | None]] = []
    for kind, start, end in event_windows(t, events):
        inside = _in_window(t, start, end)
        tw, e = t[inside], (y - r)[inside]
        rec: dict[str, str | float | None] = {"kind": kind, "start_s": start, "end_s": end}
        rec.update(dict.fromkeys(EVENT_METRICS))
        valid = np.isfinite(e)
        if valid.any():
            k = int(np.nanargmax(np.abs(e)))
            rec["peak_deviation_mmhg"] = _f(e[k])
            rec["recovery_s"] = _recovery_s(tw, e, start, band_mmhg)
            rec["iae_mmhg_s"] = _f(np.sum(np.abs(e[valid])) * ts)
        records.append(rec)
    return records


def _percent(mask: np.ndarray) -> float:
    return _f(100.0 * np.count_nonzero(mask) / mask.size)


def stable_flag(
    map_true_mmhg: Sequence[float] | np.ndarray,
    target_mmhg: Sequence[float] | np.ndarray,
    band_mmhg: float,
) -> bool:
    """True when the run shows no divergence and no sustained oscillation (module docstring)."""
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
    """All §3 metrics of one run (without the fault entries, which the runtime adds).

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
        Keys :data:`RUN_METRICS` + ``reachable`` + ``stable`` + ``disturbances``.
    """
    t, y, r, u = _as_arrays(t_s, map_mmhg, target_mmhg, rate_ml_h)
    ts = _period(t)
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
        out["steady_state_dev_mmhg"] = _f(tail.mean()) if tail.size else None
        out["iae_mmhg_s"] = _f(np.sum(e_all[ok]) * ts) if ok.any() else None
    after = t >= t0 - 1e-9
    e = (y - r)[after]
    ra = r[after]
    valid = np.isfinite(e)
    arrived = np.flatnonzero(valid & (np.abs(e) <= CLINICAL_BAND_MMHG))
    if arrived.size:
        window = e[arrived[0] :]
        window = window[np.isfinite(window)]
        out["time_in_band_pct"] = _percent(np.abs(window) <= CLINICAL_BAND_MMHG)
        out["time_below_pct"] = _percent(window < -CLINICAL_BAND_MMHG)
    else:
        out["time_in_band_pct"] = None
        out["time_below_pct"] = None
    if valid.any():
        pe = 100.0 * e[valid] / ra[valid]
        mdpe = float(np.median(pe))
        out["mdpe_pct"] = _f(mdpe)
        out["mdape_pct"] = _f(np.median(np.abs(pe)))
        out["wobble_pct"] = _f(np.median(np.abs(pe - mdpe)))
    else:
        out["mdpe_pct"] = out["mdape_pct"] = out["wobble_pct"] = None
    out["drug_total_ml"] = _f(np.sum(u) * ts / 3600.0)
    out["max_rate_ml_h"] = _f(np.max(u))
    out["time_at_limit_pct"] = _percent(u >= max_rate_ml_h * (1.0 - 1e-6))
    out.update(dict.fromkeys(STEP_WINDOW_METRICS))
    disturbances = None
    if events is not None:
        disturbances = disturbance_metrics(t, y, r, events)
        if has_step:
            first = float(disturbances[0]["start_s"]) if disturbances else math.inf  # type: ignore[arg-type]
            out.update(
                step_window_metrics(t, y, r, float(step_time_s), float(step_mmhg), first, noisy)
            )
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


def percentile_summary(values: Iterable[float | None]) -> dict[str, float | int | None]:
    """Median and 90th percentile of the non-``None`` values, with counts.

    Returns
    -------
    dict
        ``median``, ``p90`` (``None`` when no value applies), ``n`` (values used),
        ``n_null`` (``None`` values, e.g. never settled).
    """
    vals = list(values)
    used = np.array([float(v) for v in vals if v is not None], dtype=float)
    n_null = len(vals) - used.size
    if used.size == 0:
        return {"median": None, "p90": None, "n": 0, "n_null": n_null}
    return {
        "median": _f(np.median(used)),
        "p90": _f(np.percentile(used, 90.0)),
        "n": int(used.size),
        "n_null": int(n_null),
    }


def aggregate_disturbances(per_run: Sequence[Mapping[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per-event summaries across runs of one scenario, keyed by :func:`event_labels`.

    Returns
    -------
    dict
        label → ``kind``, ``start_s`` (``None`` if the runs disagree), and
        :func:`percentile_summary` of ``peak_abs_deviation_mmhg`` (|``peak_deviation_mmhg``|, so
        the 90th percentile is the severe tail for a dip and a rise alike), ``recovery_s`` and
        ``iae_mmhg_s``. Runs whose ``disturbances`` is ``None`` (events not known) are skipped.
    """
    by_label: dict[str, list[Mapping[str, Any]]] = {}
    for run in per_run:
        records = run.get("disturbances")
        if records is None:
            continue
        for label, rec in zip(event_labels([d["kind"] for d in records]), records, strict=True):
            by_label.setdefault(label, []).append(rec)
    out: dict[str, dict[str, Any]] = {}
    for label, recs in by_label.items():
        starts = {d["start_s"] for d in recs}
        peaks = [
            None if d["peak_deviation_mmhg"] is None else abs(d["peak_deviation_mmhg"])
            for d in recs
        ]
        out[label] = {
            "kind": recs[0]["kind"],
            "start_s": starts.pop() if len(starts) == 1 else None,
            "peak_abs_deviation_mmhg": percentile_summary(peaks),
            "recovery_s": percentile_summary(d["recovery_s"] for d in recs),
            "iae_mmhg_s": percentile_summary(d["iae_mmhg_s"] for d in recs),
        }
    return out


def aggregate(per_run: Sequence[Mapping[str, object]]) -> dict[str, object]:
    """Aggregate per-run metric dicts: reachable and unreachable patients reported apart.

    Returns
    -------
    dict
        ``n``, ``n_reachable``, ``n_unreachable``, ``n_unstable``, ``reachable`` /
        ``unreachable`` / ``all``: each a mapping metric → :func:`percentile_summary`, and
        ``disturbances``: :func:`aggregate_disturbances` over the reachable runs.
    """
    groups = {
        "reachable": [m for m in per_run if m.get("reachable", True)],
        "unreachable": [m for m in per_run if not m.get("reachable", True)],
        "all": list(per_run),
    }
    out: dict[str, object] = {
        "n": len(per_run),
        "n_reachable": len(groups["reachable"]),
        "n_unreachable": len(groups["unreachable"]),
        "n_unstable": sum(1 for m in per_run if not m.get("stable", True)),
    }
    for name, runs in groups.items():
        out[name] = {k: percentile_summary(m.get(k) for m in runs) for k in RUN_METRICS}  # type: ignore[misc]
    out["disturbances"] = aggregate_disturbances(groups["reachable"])
    return out
