"""Clinical performance metrics of a MAP control run (DESIGN.md §3), pure numpy.

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
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

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
RUN_METRICS = STEP_METRICS + (
    "time_in_band_pct",
    "time_below_pct",
    "mdpe_pct",
    "mdape_pct",
    "wobble_pct",
    "drug_total_ml",
    "max_rate_ml_h",
    "time_at_limit_pct",
)


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
) -> dict[str, float | bool | None]:
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

    Returns
    -------
    dict
        Keys :data:`RUN_METRICS` + ``reachable`` + ``stable``.
    """
    t, y, r, u = _as_arrays(t_s, map_mmhg, target_mmhg, rate_ml_h)
    ts = _period(t)
    has_step = step_time_s is not None and step_mmhg is not None and step_mmhg != 0.0
    if has_step:
        out: dict[str, float | bool | None] = dict(
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
    band = (
        step_band_mmhg(float(step_mmhg), noisy)
        if has_step
        else (NOISY_BAND_MMHG if noisy else CLINICAL_BAND_MMHG)
    )
    truth = y if map_true_mmhg is None else np.asarray(map_true_mmhg, dtype=float)
    out["reachable"] = bool(reachable)
    out["stable"] = stable_flag(truth, r, max(band, 1.0))
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


def aggregate(per_run: Sequence[Mapping[str, object]]) -> dict[str, object]:
    """Aggregate per-run metric dicts: reachable and unreachable patients reported apart.

    Returns
    -------
    dict
        ``n``, ``n_reachable``, ``n_unreachable``, ``n_unstable``, and ``reachable`` /
        ``unreachable`` / ``all``: each a mapping metric → :func:`percentile_summary`.
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
    return out
