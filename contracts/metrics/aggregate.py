"""Cohort summaries of per-run metrics: percentiles, reachable and unreachable patients apart."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from pressor.contracts.metrics.disturbance import event_labels
from pressor.contracts.metrics.names import RUN_METRICS
from pressor.contracts.metrics.signals import to_float


def percentile_summary(values: Iterable[float | None]) -> dict[str, float | int | None]:
    """Median, 10th and 90th percentiles of the non-``None`` values, with counts.

    Which tail is the bad one depends on the metric: p90 for errors and times, p10 for
    ``time_in_band_pct`` (:data:`pressor.contracts.metrics.names.HIGHER_IS_BETTER`).

    Returns
    -------
    dict
        ``median``, ``p10``, ``p90`` (``None`` when no value applies), ``n`` (values used),
        ``n_null`` (``None`` values, e.g. never settled).
    """
    vals = list(values)
    used = np.array([float(v) for v in vals if v is not None], dtype=float)
    n_null = len(vals) - used.size
    if used.size == 0:
        return {"median": None, "p10": None, "p90": None, "n": 0, "n_null": n_null}
    return {
        "median": to_float(np.median(used)),
        "p10": to_float(np.percentile(used, 10.0)),
        "p90": to_float(np.percentile(used, 90.0)),
        "n": int(used.size),
        "n_null": int(n_null),
    }


def percentiles_never_last(
    values: Iterable[float | None], qs: Sequence[float] = (50.0, 90.0)
) -> dict[str, float | int | None]:
    """Percentiles of a time-to-event in which ``None`` means *never* (not *unknown*).

    :func:`percentile_summary` skips a ``None``, which for ``time_to_band_s`` would drop exactly
    the patients who never reach the target and make the median look better the more of them
    there are. Here a ``None`` ranks after every number (a censored, infinite time), and a
    percentile that falls on or interpolates towards one is ``None`` ("not within the run").
    Between two numbers the interpolation is numpy's linear one.

    Parameters
    ----------
    values
        Times (any unit), ``None`` for a patient to whom the event never happened.
    qs
        Percentiles in [0, 100].

    Returns
    -------
    dict
        ``p{q:g}`` for each q (``p50`` is the median), ``n`` (all values) and ``n_never``.
    """
    vals = list(values)
    finite = sorted(float(v) for v in vals if v is not None)
    n, n_never = len(vals), len(vals) - len(finite)
    out: dict[str, float | int | None] = {}
    for q in qs:
        if n == 0:
            out[f"p{q:g}"] = None
            continue
        pos = q / 100.0 * (n - 1)
        lo = int(np.floor(pos))
        hi = min(lo + 1, n - 1)
        frac = pos - lo
        if lo >= len(finite) or (frac > 0.0 and hi >= len(finite)):
            out[f"p{q:g}"] = None  # the percentile lies among the patients who never got there
        elif frac == 0.0:
            out[f"p{q:g}"] = to_float(finite[lo])
        else:
            out[f"p{q:g}"] = to_float(finite[lo] + frac * (finite[hi] - finite[lo]))
    out["n"] = n
    out["n_never"] = n_never
    return out


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
