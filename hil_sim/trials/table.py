"""A trial's terminal table: each metric's median and bad tail in words and units, the infusion
in ml/h and µg/kg/min, and the unreachable patients with why (``pressor trial`` prints it)."""

from __future__ import annotations

from typing import Any

from pressor.contracts.metrics import HIGHER_IS_BETTER, RUN_METRICS
from pressor.contracts.metrics.labels import label
from pressor.hil_sim.trials.words import UNREACHABLE_MEANS, unreachable_lines


def _fmt(v: Any) -> str:
    if v is None:
        return "-"
    text = f"{v:.4g}" if abs(v) < 1e4 else f"{v:.0f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def format_table(summary: dict[str, Any]) -> str:
    """The terminal table: median and the bad 10 % tail of every metric, reachable patients first,
    each metric named in words with its unit (:func:`pressor.contracts.metrics.labels.label`).

    The tail is p90 for errors and times and p10 where higher is better (time in band). A ``-`` is
    a figure no patient has (``null`` counts the patients without it: docs/METRICS.md, "null
    when").
    """
    m = summary["metrics"]
    model = f", patient model {summary['patient_model']}" if "patient_model" in summary else ""
    if "target_mmhg" in summary:
        model += f", target {summary['target_mmhg']:g} mmHg (absolute)"
    width = max(len(label(k)) for k in RUN_METRICS) + 1
    lines = [
        f"trial: controller {summary['controller']}, scenario {summary['scenario']}{model},"
        f" cohort seed {summary['cohort_seed']}, {summary['n_patients']} patients:"
        f" {m['n_reachable']} reachable, {m['n_unreachable']} unreachable (listed below),"
        f" {m['n_unstable']} unstable",
        f"{'reachable patients':<{width}}{'median':>10}{'worst 10%':>10}{'n':>5}{'null':>5}"
        f" | {'unreachable: median':>19}{'worst 10%':>10}",
    ]
    for key in RUN_METRICS:
        r = m["reachable"][key]
        u = m["unreachable"][key]
        tail = "p10" if key in HIGHER_IS_BETTER else "p90"
        lines.append(
            f"{label(key):<{width}}{_fmt(r['median']):>10}{_fmt(r[tail]):>10}{r['n']:>5}"
            f"{r['n_null']:>5} | {_fmt(u['median']):>19}{_fmt(u[tail]):>10}"
        )
    for name, d in m["disturbances"].items():
        lines.append(f"{name} at {_fmt(d['start_s'])} s (reachable patients):")
        for key in ("peak_abs_deviation_mmhg", "recovery_s", "iae_mmhg_s"):
            r = d[key]
            lines.append(
                f"  {label(key):<{width - 2}}{_fmt(r['median']):>10}{_fmt(r['p90']):>10}"
                f"{r['n']:>5}{r['n_null']:>5}"
            )
    if "infusion" in summary:
        lines.append(format_infusion(summary["infusion"]))
    if "estimation" in summary:
        e = summary["estimation"]
        lines.append(
            f"schedule {summary['schedule']}: median second-half error K {_fmt(e['K_rel_err_pct'])} %,"
            f" T {_fmt(e['T_rel_err_pct'])} %, tau {_fmt(e['tau_abs_err_s'])} s"
        )
    if summary["unstable_patient_seeds"]:
        lines.append(
            "unstable (MAP not finite, or still swinging across the band in the last quarter):"
            f" patients {', '.join(str(x) for x in summary['unstable_patient_seeds'])}"
        )
    return "\n".join(lines)


def format_infusion(infusion: dict[str, Any]) -> str:
    """The table's infusion line: the drug and syringe, the weight (the reference adult said as
    such) and the median over every patient of the mean and peak rate, in ml/h and µg/kg/min."""
    w = infusion["weight_kg"]
    weight = (
        f"weight {w:g} kg"
        if infusion["weight_given"]
        else f"per kg at a {w:g} kg reference weight (no --weight-kg)"
    )

    def both(key: str) -> str:
        rate, dose = infusion[f"median_{key}_rate_ml_h"], infusion[f"median_{key}_dose_ug_kg_min"]
        return f"{_fmt(rate)} ml/h = {_fmt(dose)} µg/kg/min"

    return (
        f"infusion (median over all patients): mean {both('mean')}, peak {both('peak')};"
        f" {infusion['drug']} {infusion['concentration_ug_ml']:g} µg/ml, {weight}"
    )


def format_unreachable(records: list[dict[str, Any]]) -> str:
    """What "unreachable" means and each unreachable patient with why; ``""`` for none."""
    lines = unreachable_lines(records)
    if not lines:
        return ""
    return "\n".join([f"{UNREACHABLE_MEANS}:", *(f"  {line}" for line in lines)])
