"""Clinical performance metrics of a MAP control run, pure numpy.

``docs/METRICS.md`` defines every metric name, window, band, unit and null rule; this docstring
is the short form.

Every function takes sampled signals on a uniform tick grid (``t_s`` in s, MAP and target in mmHg,
rates in ml/h) and returns plain Python floats / bools / ``None`` under exactly the JSON names of
docs/METRICS.md. A metric that does not apply (no target step, never reached, never settled, no
valid sample) is ``None``, never a made-up number. Non-finite MAP samples (a faulted monitor
reports NaN) are ignored by every MAP metric; time-based percentages count only valid samples.

The modules: :mod:`~pressor.contracts.metrics.names` (metric names, bands, event kinds),
:mod:`~pressor.contracts.metrics.step` (one step response), :mod:`~pressor.contracts.metrics.disturbance`
(disturbance events), :mod:`~pressor.contracts.metrics.harm` (hypertension, time to the target,
divergence), :mod:`~pressor.contracts.metrics.run` (every metric of one run),
:mod:`~pressor.contracts.metrics.aggregate` (cohort summaries).

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
    has arrived (with a 5 mmHg band the settling time would make the in-band share 100 % by
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

What harms (:mod:`~pressor.contracts.metrics.harm`), from t0 (the first sample without a step):

``step_overshoot_mmhg``
    ``step_overshoot_pct`` in mmHg: max(0, max sign(Δ)·e) over the step window.
``longest_above_10_mmhg_s``
    The longest run of consecutive valid samples with e > 10 mmHg, × Ts (s); 0 if never above.
``time_to_band_s``
    First valid sample with |e| ≤ 5 mmHg, minus t0 (s); ``None`` if never.
``divergence_pct_per_h``
    Varvel's divergence: least-squares slope of |PE_k| against time (%/h).

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

from pressor.contracts.metrics.aggregate import (
    aggregate,
    aggregate_disturbances,
    percentile_summary,
    percentiles_never_last,
)
from pressor.contracts.metrics.disturbance import disturbance_metrics, event_labels, event_windows
from pressor.contracts.metrics.harm import (
    divergence_pct_per_h,
    harm_metrics,
    longest_above_s,
    step_overshoot_mmhg,
    time_to_band_s,
)
from pressor.contracts.metrics.names import (
    CLINICAL_BAND_MMHG,
    EVENT_KINDS,
    EVENT_METRICS,
    HARM_METRICS,
    HIGHER_IS_BETTER,
    NOISE_FREE_BAND_FRACTION,
    NOISY_BAND_MMHG,
    OVER_TARGET_MARGIN_MMHG,
    RUN_METRICS,
    STEP_METRICS,
    STEP_WINDOW_METRICS,
    Event,
)
from pressor.contracts.metrics.run import run_metrics, stable_flag
from pressor.contracts.metrics.step import (
    reachable_band_mmhg,
    step_band_mmhg,
    step_metrics,
    step_window_metrics,
)

__all__ = [
    "CLINICAL_BAND_MMHG",
    "EVENT_KINDS",
    "EVENT_METRICS",
    "HARM_METRICS",
    "HIGHER_IS_BETTER",
    "NOISE_FREE_BAND_FRACTION",
    "NOISY_BAND_MMHG",
    "OVER_TARGET_MARGIN_MMHG",
    "RUN_METRICS",
    "STEP_METRICS",
    "STEP_WINDOW_METRICS",
    "Event",
    "aggregate",
    "aggregate_disturbances",
    "disturbance_metrics",
    "divergence_pct_per_h",
    "event_labels",
    "event_windows",
    "harm_metrics",
    "longest_above_s",
    "percentile_summary",
    "percentiles_never_last",
    "run_metrics",
    "stable_flag",
    "reachable_band_mmhg",
    "step_band_mmhg",
    "step_metrics",
    "step_overshoot_mmhg",
    "step_window_metrics",
    "time_to_band_s",
]
