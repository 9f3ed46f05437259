"""The metric names, bands and event kinds every metric module and every caller agrees on."""

from __future__ import annotations

NOISY_BAND_MMHG = 5.0
NOISE_FREE_BAND_FRACTION = 0.02
CLINICAL_BAND_MMHG = 5.0
#: MAP more than this above the target (mmHg) is the device's hypertension that
#: ``longest_above_10_mmhg_s`` times
OVER_TARGET_MARGIN_MMHG = 10.0

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
HARM_METRICS = (
    "step_overshoot_mmhg",
    "longest_above_10_mmhg_s",
    "time_to_band_s",
    "divergence_pct_per_h",
)
"""What harms the patient (:mod:`pressor.contracts.metrics.harm`): the step overshoot in mmHg, the
longest stretch above target + 10 mmHg, the time to first reach ±5 mmHg and Varvel's divergence."""
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
    + HARM_METRICS
)
HIGHER_IS_BETTER = frozenset({"time_in_band_pct"})
"""Run metrics where a larger value is better; for every other metric a smaller one is (or, for
the signed ``mdpe_pct``, closer to zero), so the bad tail of a cohort is p10 here and p90 elsewhere."""
EVENT_KINDS = ("hemorrhage", "bolus")
"""Disturbance kinds that are events with a start; a sinusoid is continuous background."""
EVENT_METRICS = ("peak_deviation_mmhg", "recovery_s", "iae_mmhg_s")
"""The numbers of one disturbance record (besides ``kind``, ``start_s``, ``end_s``)."""

Event = tuple[str, float]
"""A disturbance event: ``(kind, start_s)``, kind in :data:`EVENT_KINDS`, start in s."""
