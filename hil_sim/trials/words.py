"""A trial's patients in words: how many were plotted, how many were not and why.

The terminal table and the report summarise the *reachable* patients (docs/METRICS.md,
"Reachable"); the others are never dropped silently: :func:`patient_counts` counts them and
:func:`unreachable_lines` says for each why (the pump's maximum cannot raise the patient's MAP by
what the scenario asks, from the record's ``max_delta_mmhg`` and ``required_delta_mmhg``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from pressor.contracts.metrics.labels import label

__all__ = ["UNREACHABLE_MEANS", "metric_label", "patient_counts", "unreachable_lines"]

#: what "unreachable" means, for a reader who meets the word in a table or a report
UNREACHABLE_MEANS = (
    "unreachable: even at the pump's maximum rate the patient's MAP cannot rise by what the"
    " scenario asks (the target step plus any disturbance's fall), so the target cannot be met"
    " by any controller; these patients are counted and listed, not mixed into the figures"
)


def patient_counts(records: Sequence[Mapping[str, Any]]) -> dict[str, int]:
    """``patients``, ``reachable``, ``unreachable`` and ``unstable`` counts of a trial's records."""
    reachable = sum(1 for r in records if r["reachable"])
    return {
        "patients": len(records),
        "reachable": reachable,
        "unreachable": len(records) - reachable,
        "unstable": sum(1 for r in records if not r.get("stable", True)),
    }


def unreachable_lines(records: Sequence[Mapping[str, Any]]) -> list[str]:
    """One line per unreachable patient: its seed and why (``patient 2026000005: the pump's
    maximum cannot raise this patient's MAP by the step: 17.7 mmHg reachable of 30.0 asked``)."""
    lines = []
    for r in records:
        if r["reachable"]:
            continue
        can, asked = r.get("max_delta_mmhg"), r.get("required_delta_mmhg")
        why = "the pump's maximum cannot raise this patient's MAP by the step"
        if can is not None and asked is not None:
            why += f": {can:.1f} mmHg reachable of {asked:.1f} asked"
        lines.append(f"patient {r['patient_seed']}: {why}")
    return lines


def metric_label(name: str) -> str:
    """A compared metric in words: ``iae_mmhg_s`` -> ``IAE (integral of |MAP - target|)
    (mmHg·s)``, ``bolus.recovery_s`` -> ``bolus: recovery (s)``."""
    event, _, metric = name.rpartition(".")
    if event and metric == "peak_deviation_mmhg":  # compared by magnitude (paired.py)
        metric = "peak_abs_deviation_mmhg"
    return f"{event}: {label(metric)}" if event else label(metric)
