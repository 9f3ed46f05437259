"""Step-response metrics: overshoot, rise and settling time, steady-state deviation, IAE.

Definitions: the package docstring (:mod:`pressor.contracts.metrics`) and docs/METRICS.md.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pressor.contracts.metrics.names import (
    CLINICAL_BAND_MMHG,
    NOISE_FREE_BAND_FRACTION,
    NOISY_BAND_MMHG,
    STEP_METRICS,
    STEP_WINDOW_METRICS,
)
from pressor.contracts.metrics.signals import (
    TIME_EPS_S,
    as_arrays,
    first_crossing,
    period,
    to_float,
)


def step_band_mmhg(step_mmhg: float, noisy: bool) -> float:
    """Settling band (mmHg): 2 % of |Δ| for noise-free runs, 5 mmHg for noisy runs."""
    return NOISY_BAND_MMHG if noisy else NOISE_FREE_BAND_FRACTION * abs(step_mmhg)


def reachable_band_mmhg(step_mmhg: float | None, noisy: bool) -> float:
    """The band ``reachable`` is judged against (mmHg): the run's settling band
    (:func:`step_band_mmhg`), or the clinical band when it has no target step. A patient the pump
    cannot bring within it of the target is unreachable (docs/METRICS.md)."""
    return CLINICAL_BAND_MMHG if step_mmhg is None else step_band_mmhg(step_mmhg, noisy)


def step_metrics(
    t_s: Sequence[float] | np.ndarray,
    map_mmhg: Sequence[float] | np.ndarray,
    target_mmhg: Sequence[float] | np.ndarray | float,
    step_time_s: float,
    step_mmhg: float,
    noisy: bool = False,
    band_mmhg: float | None = None,
) -> dict[str, float | None]:
    """Step-response metrics of one run (definitions: docs/METRICS.md).

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
    t, y, r = as_arrays(t_s, map_mmhg, target_mmhg)
    if step_mmhg == 0.0 or not np.isfinite(step_mmhg):
        raise ValueError(f"step_mmhg must be finite and non-zero, got {step_mmhg!r}")
    band = step_band_mmhg(step_mmhg, noisy) if band_mmhg is None else float(band_mmhg)
    ts = period(t)
    after = t >= step_time_s - 1e-9
    ta, ya, ra = t[after], y[after], r[after]
    valid = np.isfinite(ya)
    out: dict[str, float | None] = dict.fromkeys(STEP_METRICS)
    if not valid.any():
        return out
    sign = 1.0 if step_mmhg > 0 else -1.0
    # Error in the direction of the step: positive means past the target.
    e_dir = sign * (ya - ra)
    out["overshoot_pct"] = to_float(100.0 * max(0.0, float(np.nanmax(e_dir))) / abs(step_mmhg))
    progress = sign * (ya - (ra - step_mmhg))  # 0 at the old level, |Δ| at the target
    t10 = first_crossing(ta, progress, 0.1 * abs(step_mmhg))
    t90 = first_crossing(ta, progress, 0.9 * abs(step_mmhg))
    out["rise_time_s"] = None if t10 is None or t90 is None else to_float(t90 - t10)
    err = np.abs(ya - ra)
    outside = np.flatnonzero(valid & (err > band))
    last_valid = int(np.flatnonzero(valid)[-1])
    if outside.size == 0:
        out["settling_time_s"] = 0.0
    elif outside[-1] == last_valid:
        out["settling_time_s"] = None
    else:
        out["settling_time_s"] = to_float(ta[outside[-1]] - step_time_s)
    n_tail = max(1, int(round(0.1 * t.size)))
    tail = np.abs(y[-n_tail:] - r[-n_tail:])
    tail = tail[np.isfinite(tail)]
    out["steady_state_dev_mmhg"] = to_float(tail.mean()) if tail.size else None
    out["iae_mmhg_s"] = to_float(np.sum(err[valid]) * ts)
    return out


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
    t, y, r = as_arrays(t_s, map_mmhg, target_mmhg)
    out: dict[str, float | None] = dict.fromkeys(STEP_WINDOW_METRICS)
    keep = t < end_s - TIME_EPS_S
    if np.count_nonzero(keep & (t >= step_time_s - TIME_EPS_S)) < 2:
        return out
    m = step_metrics(t[keep], y[keep], r[keep], step_time_s, step_mmhg, noisy=noisy)
    for name in STEP_WINDOW_METRICS:
        out[name] = m[name.removeprefix("step_")]
    return out
