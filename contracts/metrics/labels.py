"""The metrics as a person reads them: a name in words, a unit, a resolution and why a null is null.

The JSON records (``patients.json``, a ``--summary`` file) keep the snake_case names of
docs/METRICS.md, which programs read; what a terminal, a report or a table shows a person comes
from here: :func:`label` (``mdpe_pct`` -> ``MDPE (median performance error)``), :func:`format_value`
(``-0.0001`` % -> ``0.0 %``: rounded to the metric's resolution, never a negative zero) and
:func:`null_reason` (why a metric has no value, in the words of docs/METRICS.md's "null when").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

__all__ = ["MetricLabel", "LABELS", "format_number", "format_value", "label", "null_reason"]


@dataclass(frozen=True)
class MetricLabel:
    """How one metric is shown to a person.

    Attributes
    ----------
    name
        The metric in words (``time within ±5 mmHg of the target``).
    unit
        Its unit as printed (``%``, ``s``, ``mmHg``, ``mmHg·s``, ``ml``, ``ml/h``, ``%/h``), ``""``
        for a count or a yes/no.
    decimals
        The resolution worth reading (the JSON keeps full precision).
    null_why
        Why the value can be absent (docs/METRICS.md, "null when"), ``""`` when it never is.
    """

    name: str
    unit: str
    decimals: int
    null_why: str = ""


_NO_STEP = "no target step in this run"
_NO_SAMPLE = "no valid MAP sample"
_NEVER_BAND = "MAP never came within 5 mmHg of the target"
_STEP_WINDOW = (
    "no target step, a disturbance at or before the step, or the scenario's disturbances not"
    " known (pressor run does not know the device's scenario)"
)

#: metric name (docs/METRICS.md) -> how it is shown
LABELS: dict[str, MetricLabel] = {
    "overshoot_pct": MetricLabel("overshoot, whole run (disturbances too)", "%", 1, _NO_STEP),
    "rise_time_s": MetricLabel(
        "rise time (10 to 90 % of the step)", "s", 1, "90 % of the step was never reached"
    ),
    "settling_time_s": MetricLabel(
        "settling time", "s", 1, "never settled: still outside the settling band at the end"
    ),
    "steady_state_dev_mmhg": MetricLabel(
        "steady-state deviation (last 10 %)", "mmHg", 1, "no valid MAP sample in the last 10 %"
    ),
    "iae_mmhg_s": MetricLabel("IAE (integral of |MAP - target|)", "mmHg·s", 0, _NO_SAMPLE),
    "time_in_band_pct": MetricLabel("time within ±5 mmHg of the target", "%", 1, _NEVER_BAND),
    "time_below_pct": MetricLabel("time more than 5 mmHg below", "%", 1, _NEVER_BAND),
    "mdpe_pct": MetricLabel("MDPE (median performance error)", "%", 1, _NO_SAMPLE),
    "mdape_pct": MetricLabel("MDAPE (median absolute performance error)", "%", 1, _NO_SAMPLE),
    "wobble_pct": MetricLabel("wobble (spread of the performance error)", "%", 1, _NO_SAMPLE),
    "drug_total_ml": MetricLabel("drug given", "ml", 2),
    "max_rate_ml_h": MetricLabel("highest infusion rate", "ml/h", 1),
    "time_at_limit_pct": MetricLabel("time at the pump's maximum", "%", 1),
    "step_overshoot_pct": MetricLabel("step: overshoot", "%", 1, _STEP_WINDOW),
    "step_rise_time_s": MetricLabel(
        "step: rise time (10 to 90 %)",
        "s",
        1,
        _STEP_WINDOW + "; or 90 % not reached before the first disturbance",
    ),
    "step_settling_time_s": MetricLabel(
        "step: settling time",
        "s",
        1,
        _STEP_WINDOW + "; or still outside the band when the first disturbance started",
    ),
    "step_iae_mmhg_s": MetricLabel("step: IAE", "mmHg·s", 0, _STEP_WINDOW),
    "step_overshoot_mmhg": MetricLabel("step: overshoot above the target", "mmHg", 1, _STEP_WINDOW),
    "longest_above_10_mmhg_s": MetricLabel(
        "longest time more than 10 mmHg above the target", "s", 1, _NO_SAMPLE
    ),
    "time_to_band_s": MetricLabel("time to within ±5 mmHg", "s", 1, _NEVER_BAND),
    "divergence_pct_per_h": MetricLabel(
        "divergence (trend of the error; < 0: shrinking)", "%/h", 1, "fewer than two valid samples"
    ),
    "reachable": MetricLabel("target reachable at the pump's maximum", "", 0),
    "stable": MetricLabel("stable (no sustained oscillation)", "", 0),
    "commands_out_of_range": MetricLabel("commands outside [0, pump maximum]", "", 0),
    # a disturbance event's record
    "peak_deviation_mmhg": MetricLabel("peak deviation", "mmHg", 1, "no valid MAP sample"),
    "peak_abs_deviation_mmhg": MetricLabel("peak |deviation|", "mmHg", 1, "no valid MAP sample"),
    "recovery_s": MetricLabel(
        "recovery", "s", 1, "never back within ±5 mmHg before the window ended"
    ),
}


def label(key: str) -> str:
    """``key``'s name in words with its unit in brackets (``time within ±5 mmHg of the target
    (%)``); an unknown key is returned as it is."""
    lab = LABELS.get(key)
    if lab is None:
        return key
    return f"{lab.name} ({lab.unit})" if lab.unit else lab.name


def format_number(value: float, decimals: int) -> str:
    """``value`` to ``decimals`` places, without a negative zero (``-0.0001`` -> ``0.0``)."""
    text = f"{value:.{decimals}f}"
    if text.startswith("-") and float(text) == 0.0:
        text = text[1:]
    return text


def format_value(key: str, value: Any) -> str:
    """``value`` of metric ``key`` for a person: rounded to its resolution, with its unit
    (``0.12 % -> 0.1 %``), ``yes`` / ``no`` for a truth, ``not measured`` for a null (the reason:
    :func:`null_reason`)."""
    lab = LABELS.get(key)
    if value is None:
        return "not measured"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int | float):
        if isinstance(value, float) and not math.isfinite(value):
            return "not measured"
        if lab is None:
            return f"{value:.4g}" if isinstance(value, float) else str(value)
        if isinstance(value, int) and not lab.unit:
            return str(value)
        text = format_number(float(value), lab.decimals)
        return f"{text} {lab.unit}" if lab.unit else text
    return str(value)


def null_reason(key: str, metrics: dict[str, Any] | None = None) -> str:
    """Why metric ``key`` has no value; with the run's ``metrics`` the reason that applies to it
    (no step in the run, the disturbances not known) when it can be told, else the documented
    ones."""
    if metrics is not None:
        no_step = metrics.get("overshoot_pct") is None and metrics.get("iae_mmhg_s") is not None
        if no_step and key in (
            "overshoot_pct",
            "rise_time_s",
            "settling_time_s",
            "step_overshoot_pct",
            "step_rise_time_s",
            "step_settling_time_s",
            "step_iae_mmhg_s",
            "step_overshoot_mmhg",
        ):
            return _NO_STEP
        if (
            key.startswith("step_")
            and "disturbances" in metrics
            and metrics["disturbances"] is None
        ):
            return "the scenario's disturbances are not known (pressor run does not know it)"
        if key.startswith("step_") and metrics.get(key.removeprefix("step_")) is not None:
            return {
                "step_rise_time_s": "90 % of the step not reached before the first disturbance",
                "step_settling_time_s": "still outside the band when the first disturbance came",
            }.get(key, "the first disturbance came at or before the step")
    lab = LABELS.get(key)
    return lab.null_why if lab is not None and lab.null_why else "not defined for this run"
