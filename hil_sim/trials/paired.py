"""Paired per-patient comparison of two controllers run on the same cohort.

Every patient of a trial is drawn from the cohort seed, so two controllers run on the same seed
meet the same patients in the same order: a per-patient difference removes the between-patient
spread that dominates unpaired medians. For each metric this module reports, over the patients
where both runs have a value (reachable in both, metric not null):

* ``n`` — the number of such pairs;
* ``win_rate_pct`` — the share of pairs where the first controller is strictly better (lower, or
  higher for :data:`pressor.contracts.metrics.HIGHER_IS_BETTER`);
* ``wins``, ``ties``, ``losses`` — the pairs where the first controller is better, equal (within
  :data:`TIE_REL` of the larger magnitude: 100 % against 100 % in band is a tie, not a loss) and
  worse; every table shows these three, since a win rate alone counts ties as losses;
* ``median_ratio`` — the median over pairs of first/second (pairs whose second value is 0 are left
  out of the ratio; ``None`` when none is left);
* ``median_difference`` — the median of first − second, in the metric's unit;
* ``wilcoxon_p`` — the two-sided Wilcoxon signed-rank p-value of the differences (``None`` for
  fewer than 6 pairs or when every difference is zero; zero differences are dropped, as Wilcoxon's
  original test does).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy.stats import wilcoxon

from pressor.contracts.metrics import HIGHER_IS_BETTER

#: scalar metrics compared (``docs/METRICS.md`` defines each), lower is better unless listed below
PAIRED_METRICS: tuple[str, ...] = (
    "iae_mmhg_s",
    "step_iae_mmhg_s",
    "step_overshoot_pct",
    "step_settling_time_s",
    "time_in_band_pct",
    "time_below_pct",
    "drug_total_ml",
)
#: per-disturbance metrics compared, per event label (``hemorrhage``, ``bolus``, …)
EVENT_PAIRED_METRICS: tuple[str, ...] = ("peak_deviation_mmhg", "recovery_s", "iae_mmhg_s")
#: pairs below this count get no p-value (the signed-rank test has no power there)
MIN_PAIRS_FOR_P = 6
#: two values closer than this fraction of the larger magnitude are a tie (float noise is no win)
TIE_REL = 1e-9


def _event_values(record: Mapping[str, Any]) -> dict[str, float | None]:
    """``LABEL.metric`` -> value for the record's disturbances (peak judged by magnitude)."""
    out: dict[str, float | None] = {}
    seen: dict[str, int] = {}
    for d in record.get("disturbances", []):
        seen[d["kind"]] = seen.get(d["kind"], 0) + 1
        label = d["kind"] if seen[d["kind"]] == 1 else f"{d['kind']}_{seen[d['kind']]}"
        for m in EVENT_PAIRED_METRICS:
            v = d.get(m)
            out[f"{label}.{m}"] = None if v is None else abs(v) if m.startswith("peak") else v
    return out


def _values(record: Mapping[str, Any]) -> dict[str, float | None]:
    vals: dict[str, float | None] = {m: record.get(m) for m in PAIRED_METRICS}
    vals.update(_event_values(record))
    return vals


def compare_pair(
    first: Sequence[Mapping[str, Any]], second: Sequence[Mapping[str, Any]]
) -> dict[str, dict[str, Any]]:
    """Paired statistics of ``first`` against ``second``, one entry per metric.

    Parameters
    ----------
    first, second
        Per-patient trial records (``patients.json``) of the same cohort, in the same order.

    Returns
    -------
    dict
        ``metric -> {n, win_rate_pct, median_ratio, median_difference, wilcoxon_p}``.

    Raises
    ------
    ValueError
        The two lists are not the same patients in the same order.
    """
    seeds_a = [r["patient_seed"] for r in first]
    seeds_b = [r["patient_seed"] for r in second]
    if seeds_a != seeds_b:
        raise ValueError("paired comparison needs the same patients in the same order")
    per_patient = [
        (_values(a), _values(b))
        for a, b in zip(first, second, strict=True)
        if a["reachable"] and b["reachable"]
    ]
    metrics = list(per_patient[0][0]) if per_patient else list(PAIRED_METRICS)
    return {m: _stats(m, per_patient) for m in metrics}


def _stats(metric: str, pairs: list[tuple[dict, dict]]) -> dict[str, Any]:
    a = np.array([p[0].get(metric) for p in pairs if _both(p, metric)], dtype=float)
    b = np.array([p[1].get(metric) for p in pairs if _both(p, metric)], dtype=float)
    n = int(a.size)
    if n == 0:
        return {
            "n": 0,
            "win_rate_pct": None,
            "median_ratio": None,
            "median_difference": None,
            "wilcoxon_p": None,
            "wins": 0,
            "ties": 0,
            "losses": 0,
        }
    higher = metric.split(".")[-1] in HIGHER_IS_BETTER
    ties = np.abs(a - b) <= TIE_REL * np.maximum(np.abs(a), np.abs(b))
    wins = ((a > b) if higher else (a < b)) & ~ties
    nonzero = b != 0.0
    diff = a - b
    p_value = None
    if n >= MIN_PAIRS_FOR_P and np.any(diff != 0.0):
        p_value = float(wilcoxon(a, b, zero_method="wilcox", alternative="two-sided").pvalue)
    return {
        "n": n,
        "win_rate_pct": float(100.0 * np.mean(wins)),
        "median_ratio": float(np.median(a[nonzero] / b[nonzero])) if np.any(nonzero) else None,
        "median_difference": float(np.median(diff)),
        "wilcoxon_p": p_value,
        "wins": int(np.count_nonzero(wins)),
        "ties": int(np.count_nonzero(ties)),
        "losses": int(n - np.count_nonzero(wins) - np.count_nonzero(ties)),
    }


def _both(pair: tuple[dict, dict], metric: str) -> bool:
    va, vb = pair[0].get(metric), pair[1].get(metric)
    return va is not None and vb is not None and math.isfinite(va) and math.isfinite(vb)


def compare_controllers(
    records: Mapping[str, Sequence[Mapping[str, Any]]],
) -> dict[str, dict[str, dict[str, Any]]]:
    """The first controller against each of the others: ``"A vs B" -> metric -> statistics``.

    Parameters
    ----------
    records
        Controller spec -> its per-patient records, in the order the user named the controllers.
    """
    names = list(records)
    head = names[0]
    return {
        f"{head} vs {other}": compare_pair(records[head], records[other]) for other in names[1:]
    }


#: the statistics of one metric, in the order every table shows them (``wins``, ``ties`` and
#: ``losses`` are one cell, ``W/T/L``, in place of the win rate)
STAT_KEYS = ("n", "win_rate_pct", "median_ratio", "median_difference", "wilcoxon_p")
#: the column heads of :func:`stat_cells`
STAT_HEADS = ("n", "wins / ties / losses", "median ratio", "median diff", "Wilcoxon p")


def stat_cells(stats: Mapping[str, Any]) -> list[str]:
    """One metric's statistics as table cells, in :data:`STAT_HEADS` order (3 digits, "—" for
    null): ``n``, ``wins / ties / losses`` (``3 / 2 / 1``), the median ratio and difference and p."""

    def cell(k: str) -> str:
        v = stats[k]
        return "—" if v is None else f"{v:.3g}" if isinstance(v, float) else str(v)

    wtl = "—" if not stats["n"] else f"{stats['wins']} / {stats['ties']} / {stats['losses']}"
    return [cell("n"), wtl, *(cell(k) for k in STAT_KEYS[2:])]


def format_comparison(comparison: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> str:
    """A terminal table of :func:`compare_controllers`: one block per pair, one row per metric
    named in words (:func:`pressor.hil_sim.trials.words.metric_label`)."""
    from pressor.hil_sim.trials.words import metric_label

    lines = []
    for pair, metrics in comparison.items():
        width = max([len(metric_label(m)) for m in metrics] + [6])
        lines.append(
            f"paired: {pair} (patients reachable in both; wins / ties / losses of the first;"
            " ratio and diff: first against second)"
        )
        lines.append(
            f"  {'metric':<{width}} {'n':>4} {'W / T / L':>13} {'ratio':>7} {'diff':>9} {'p':>8}"
        )
        for metric, st in metrics.items():
            n, wtl, ratio, diff, p = stat_cells(st)
            lines.append(
                f"  {metric_label(metric):<{width}} {n:>4} {wtl:>13} {ratio:>7} {diff:>9} {p:>8}"
            )
    return "\n".join(lines)
