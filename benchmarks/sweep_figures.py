"""The sensitivity sweep's figures, its tables and its throughput meter
(:mod:`benchmarks.sensitivity_sweep`).

A *row* is one (model, level, controller, syringe) group of patient records, as ``pressor
trial`` writes them (every metric judges the true MAP, docs/METRICS.md). :func:`row_figures`
reduces it to what harms, in the order the issue puts it: hypertension first, then the time a
hypotensive patient waits, then the time in the band, then the Varvel figures. Patients a figure
does not apply to are not silently dropped: a patient who never comes within ±5 mmHg ranks after
every time in ``time_to_band_s`` (:func:`pressor.contracts.metrics.percentiles_never_last`) and counts 0 %
in the band.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from pressor.contracts.metrics import percentile_summary, percentiles_never_last

#: a hypertensive stretch (MAP > target + 10 mmHg) longer than this (s) counts against the patient
LONG_ABOVE_S = 30.0


def _spread(values: Sequence[float | None], tail: str = "p90") -> dict[str, float | None]:
    """Median, the bad tail (``p90`` or ``p10``) and the worst value of the non-null values."""
    summary = percentile_summary(values)
    used = [float(v) for v in values if v is not None]
    worst = (max(used) if tail == "p90" else min(used)) if used else None
    return {"median": summary["median"], tail: summary[tail], "worst": worst}


def _median(values: Sequence[float | None]) -> float | None:
    return percentile_summary(values)["median"]  # type: ignore[return-value]


def row_figures(records: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The figures of one row of patients.

    Returns
    -------
    dict
        ``patients``, ``unstable`` (counts); ``step_overshoot_pct`` (% of the step) and
        ``step_overshoot_mmhg`` (mmHg): ``median``, ``p90``, ``worst`` (the max);
        ``longest_above_10_mmhg_s`` (s, the same three); ``above_10_mmhg_over_30_s`` (patients
        with a stretch above target + 10 mmHg longer than :data:`LONG_ABOVE_S`) and its share
        ``above_10_mmhg_over_30_s_pct`` (%); ``time_to_band_s`` (s): ``p50``, ``p90``, ``n_never``;
        ``time_below_pct`` (% after arrival, never-arrived patients left out): ``median``, ``p90``,
        ``worst``; ``time_in_band_pct`` (% after arrival, never-arrived counted 0): ``median``,
        ``p10``, ``worst``; medians ``mdpe_pct``, ``mdape_pct``, ``wobble_pct`` (%),
        ``divergence_pct_per_h`` (%/h), ``iae_mmhg_s`` (mmHg·s); ``hour_limited`` (patients whose
        command the hourly dose limit cut at least once; 0 without dose limits); ``held``
        (patients the supervisor put in HOLD or FAILSAFE for at least one tick).
    """
    n = len(records)
    longest = [r["longest_above_10_mmhg_s"] for r in records]
    over = sum(1 for v in longest if v is not None and v > LONG_ABOVE_S)
    to_band = percentiles_never_last(r["time_to_band_s"] for r in records)
    in_band = [0.0 if r["time_in_band_pct"] is None else r["time_in_band_pct"] for r in records]
    return {
        "patients": n,
        "unstable": sum(not r["stable"] for r in records),
        "step_overshoot_pct": _spread([r["step_overshoot_pct"] for r in records]),
        "step_overshoot_mmhg": _spread([r["step_overshoot_mmhg"] for r in records]),
        "longest_above_10_mmhg_s": _spread(longest),
        "above_10_mmhg_over_30_s": over,
        "above_10_mmhg_over_30_s_pct": 100.0 * over / n if n else None,
        "time_to_band_s": {
            "p50": to_band["p50"],
            "p90": to_band["p90"],
            "n_never": to_band["n_never"],
        },  # fmt: skip
        "time_below_pct": _spread([r["time_below_pct"] for r in records]),
        "time_in_band_pct": _spread(in_band, tail="p10"),
        "mdpe_pct": _median([r["mdpe_pct"] for r in records]),
        "mdape_pct": _median([r["mdape_pct"] for r in records]),
        "wobble_pct": _median([r["wobble_pct"] for r in records]),
        "divergence_pct_per_h": _median([r["divergence_pct_per_h"] for r in records]),
        "iae_mmhg_s": _median([r["iae_mmhg_s"] for r in records]),
        "hour_limited": sum(1 for r in records if r.get("dose", {}).get("hour_limited_s", 0) > 0),
        "held": sum(1 for r in records if r.get("held_s", 0) > 0),
    }


def shortfall_figures(shortfalls_mmhg: Sequence[float]) -> dict[str, float | None]:
    """Median and largest shortfall (mmHg) of the non-responders: how far the best the limits can
    hold falls short of the scenario's ask (:func:`pressor.hil_sim.reach.hold_shortfall_mmhg`)."""
    if not shortfalls_mmhg:
        return {"median": None, "worst": None}
    return {
        "median": float(np.median(shortfalls_mmhg)),
        "worst": float(max(shortfalls_mmhg)),
    }


def _num(value: float | None, digits: int = 1) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _triple(d: dict[str, float | None], tail: str, digits: int = 1) -> str:
    return " / ".join(_num(d[k], digits) for k in ("median", tail, "worst"))


def _to_band(d: dict[str, Any]) -> str:
    """``median / p90`` (s), ``never`` for a percentile among the never-arrived, and their count."""
    text = " / ".join("never" if d[k] is None else f"{d[k]:.0f}" for k in ("p50", "p90"))
    return f"{text} ({d['n_never']} never)" if d["n_never"] else text


HEADER = (
    "| level | controller | syringe µg/ml | patients | unstable"
    " | step overshoot % (median / p90 / max) | step overshoot mmHg (median / p90 / max)"
    " | longest above target + 10 mmHg, s (median / p90 / max) | > 30 s above target + 10 mmHg"
    " | to ±5 mmHg, s (median / p90) | below −5 mmHg after entry, % (median / p90 / max)"
    " | in ±5 mmHg after entry, % (median / p10 / min) | MDPE % | MDAPE % | wobble %"
    " | divergence %/h | IAE mmHg·s | hour-limited | HOLD/FAILSAFE |\n"
    "| ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
    " ---: | ---: | ---: | ---: | ---: | ---: |"
)


def format_row(level: float, controller: str, syringe: str, fig: dict[str, Any]) -> str:
    """One Markdown row of :data:`HEADER` (``syringe``: the concentration, marked if switched)."""
    over = f"{fig['above_10_mmhg_over_30_s']} ({_num(fig['above_10_mmhg_over_30_s_pct'])} %)"
    return (
        f"| {level:g}× | {controller} | {syringe} | {fig['patients']} | {fig['unstable']}"
        f" | {_triple(fig['step_overshoot_pct'], 'p90')}"
        f" | {_triple(fig['step_overshoot_mmhg'], 'p90')}"
        f" | {_triple(fig['longest_above_10_mmhg_s'], 'p90', 0)} | {over}"
        f" | {_to_band(fig['time_to_band_s'])} | {_triple(fig['time_below_pct'], 'p90')}"
        f" | {_triple(fig['time_in_band_pct'], 'p10')} | {_num(fig['mdpe_pct'], 2)}"
        f" | {_num(fig['mdape_pct'], 2)} | {_num(fig['wobble_pct'], 2)}"
        f" | {_num(fig['divergence_pct_per_h'], 2)} | {_num(fig['iae_mmhg_s'], 0)}"
        f" | {fig['hour_limited']} | {fig['held']} |"
    )


REACH_HEADER = (
    "| level | patients | reach the target, standard syringe | switched to the stronger syringe"
    " | non-responders | non-responders' shortfall, mmHg (median / max) |\n"
    "| ---: | ---: | ---: | ---: | ---: | ---: |"
)


def format_reach_row(level: float, reach: dict[str, Any]) -> str:
    """One Markdown row of :data:`REACH_HEADER` from a level's ``reach`` entry."""
    short = reach["shortfall_mmhg"]
    switched = reach["switched"]
    if reach["stronger_syringe_ug_ml"] is None:
        switched_text = "- (none in the library)"
    else:
        switched_text = f"{switched} (to {reach['stronger_syringe_ug_ml']:g} µg/ml)"
    return (
        f"| {level:g}× | {reach['patients']} | {reach['standard']} | {switched_text}"
        f" | {reach['non_responders']} | {_num(short['median'])} / {_num(short['worst'])} |"
    )


HEADLINE_HEADER = (
    "| level | controller | responders | unstable | step overshoot %, p90 / max"
    " | > 30 s above target + 10 mmHg, % of patients | to ±5 mmHg, s (median / p90)"
    " | in ±5 mmHg after entry, % (median) | IAE mmHg·s (median) |\n"
    "| ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
)


def format_headline_row(level: float, controller: str, fig: dict[str, Any]) -> str:
    """One Markdown row of :data:`HEADLINE_HEADER`: issue 41's figures over every patient brought
    to the target (the standard syringe's and the switched ones together)."""
    os_ = fig["step_overshoot_pct"]
    return (
        f"| {level:g}× | {controller} | {fig['patients']} | {fig['unstable']}"
        f" | {_num(os_['p90'])} / {_num(os_['worst'])}"
        f" | {_num(fig['above_10_mmhg_over_30_s_pct'])} | {_to_band(fig['time_to_band_s'])}"
        f" | {_num(fig['time_in_band_pct']['median'])} | {_num(fig['iae_mmhg_s'], 0)} |"
    )


def model_tables(model: str, result: dict[str, Any]) -> str:
    """The Markdown of one model: its heading, who reaches the target, the figures."""
    std, strong = result["standard_syringe"], result["stronger_syringe"]
    lines = [
        f"### {model} ({result['drug']}; standard syringe {std['concentration_ug_ml']:g} µg/ml,"
        f" command ≤ {std['hard_max_ml_h']:g} ml/h and ≤ {std['max_ml_per_hour']:g} ml per hour,"
        f" held ≤ {std['max_rate_ml_h']:g} ml/h"
        + (
            f"; stronger syringe {strong['concentration_ug_ml']:g} µg/ml,"
            f" ≤ {strong['hard_max_ml_h']:g} ml/h and ≤ {strong['max_ml_per_hour']:g} ml per hour,"
            f" held ≤ {strong['max_rate_ml_h']:g} ml/h"
            if strong
            else "; no stronger syringe in the library"
        )
        + ")",
        "",
        REACH_HEADER,
        *(format_reach_row(lv["level"], lv["reach"]) for lv in result["levels"]),
        "",
        "Every patient brought to the target (the standard syringe's and the switched together):",
        "",
        HEADLINE_HEADER,
        *(
            format_headline_row(lv["level"], row["controller"], row["figures"])
            for lv in result["levels"]
            for row in lv["responders"]
        ),
        "",
        "Every group apart (the switched and the non-responders marked):",
        "",
        HEADER,
    ]
    for lv in result["levels"]:
        for row in lv["rows"]:
            syringe = f"{row['syringe_ug_ml']:g}"
            if row["group"] != "standard":
                syringe += f" ({row['group']})"
            lines.append(format_row(lv["level"], row["controller"], syringe, row["figures"]))
    return "\n".join(lines)


class Throughput:
    """Simulated patient-hours against wall and worker CPU time (s), for the stderr report.

    Per core is per CPU minute of the workers: on a shared host the wall time also counts the
    other processes' use of the cores, the CPU time only this sweep's.
    """

    def __init__(self) -> None:
        self.wall_s = 0.0
        #: (model, controller) -> [patient-hours, worker CPU s]
        self.by_run: dict[tuple[str, str], list[float]] = {}
        #: model -> part -> why its runs ran that part without a compiled twin
        self.plain: dict[str, dict[str, set[str]]] = {}

    def add(
        self, wall_s: float, runs: list[tuple[str, str, float, float, tuple[tuple[str, str], ...]]]
    ) -> None:
        """Count one batch: its wall time (s) and per run (model, controller, patient-hours,
        CPU s, the (part, why) it ran without a compiled twin)."""
        self.wall_s += wall_s
        for model, controller, hours, cpu, plain in runs:
            acc = self.by_run.setdefault((model, controller), [0.0, 0.0])
            acc[0] += hours
            acc[1] += cpu
            parts = self.plain.setdefault(model, {})
            for part, why in plain:
                parts.setdefault(part, set()).add(why)

    def report(self, jobs: int) -> str:
        """The totals, then patient-hours per CPU minute per model (with the parts that ran
        without their compiled twin) and per model and controller."""
        hours = sum(h for h, _ in self.by_run.values())
        cpu = sum(c for _, c in self.by_run.values())
        if self.wall_s <= 0.0 or cpu <= 0.0:
            return "throughput: nothing ran (every cohort reused)"
        lines = [
            f"throughput: {hours:.1f} patient-hours in {self.wall_s:.1f} s wall:"
            f" {hours / (self.wall_s / 60.0):.1f} patient-hours per wall minute with {jobs}"
            f" job(s), {hours / (cpu / 60.0):.1f} per CPU minute of the workers (per busy core)"
        ]
        models: dict[str, list[float]] = {}
        for (model, _), (h, c) in self.by_run.items():
            acc = models.setdefault(model, [0.0, 0.0])
            acc[0] += h
            acc[1] += c
        for model, (h, c) in models.items():
            plain = self.plain.get(model, {})
            twins = (
                "without compiled twin: "
                + "; ".join(f"{part} ({', '.join(sorted(plain[part]))})" for part in sorted(plain))
                if plain
                else "compiled twins: patient, controller, dose guard"
            )
            lines.append(f"  {model}: {h / (c / 60.0):.1f} per CPU minute ({twins})")
        for (model, controller), (h, c) in self.by_run.items():
            lines.append(f"  {model} {controller}: {h / (c / 60.0):.1f} per CPU minute")
        return "\n".join(lines)
