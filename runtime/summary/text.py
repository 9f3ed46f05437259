"""The summary of a runtime run for a person: the lines ``pressor run`` and ``pressor sil`` print.

:func:`print_summary` names every figure in words with its unit
(:mod:`pressor.contracts.metrics.labels`), the faults in words, the supervisor's states, the
patient's start MAP and target, the drug and the dose; :func:`run_context` gathers what those
lines need besides the metrics; :func:`print_fault_table` the scored fault list;
:func:`replay_command` the command that replays the recording on this machine. The JSON summary
they read is :func:`pressor.runtime.summary.build_summary`'s.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from typing import Any

import numpy as np

from pressor.contracts.drug import REFERENCE_WEIGHT_KG
from pressor.contracts.metrics.labels import LABELS, format_number, format_value, null_reason
from pressor.runtime.core.fault_words import describe_detections
from pressor.runtime.inputs.clinician import describe_target
from pressor.runtime.shell.viewer import has_display


def replay_command(rrd: Any, environ: Mapping[str, str] | None = None) -> str:
    """The command that replays ``rrd`` on this machine: the native viewer where there is a
    display (``DISPLAY`` or ``WAYLAND_DISPLAY`` set), else the web viewer on localhost (the
    native one fails without a display; docs/VIEWER.md)."""
    if has_display(environ):
        return f"rerun {rrd}"
    return f"rerun --web-viewer --bind 127.0.0.1 {rrd}  (no display here: open the printed URL)"


def _fmt(v: Any, key: str = "") -> str:
    """``v`` for a human: a metric rounded to its resolution with its unit, no negative zero
    (:func:`pressor.contracts.metrics.labels.format_value`); else 4 significant digits, ``-`` for
    a null."""
    if v is None:
        return "-"
    if key in LABELS:
        return format_value(key, v)
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _dose(x: float) -> str:
    """A dose rate to 3 significant digits, without an exponent (0.0238, 2.57, 180)."""
    if x == 0.0:
        return "0"
    text = f"{x:.3g}"
    return f"{x:.{max(0, 2 - math.floor(math.log10(abs(x))))}f}" if "e" in text else text


#: the supervisor's states in words
_STATE_WORDS = {
    "STARTUP": "starting",
    "AUTO": "automatic control",
    "HOLD": "rate held on a fault",
    "FAILSAFE": "fail-safe rate",
    "RECOVERING": "returning to automatic control",
    "STOPPED": "stopped by the clinician",
    "MANUAL": "the clinician's manual rate",
}


def _name(key: str) -> str:
    """A metric's name in words (its unit is printed with the value)."""
    return LABELS[key].name if key in LABELS else key


def run_context(
    summary: dict[str, Any],
    result: Any = None,
    drug: Any = None,
    weight_kg: float | None = None,
) -> dict[str, Any]:
    """What a person reading the summary needs besides the metrics: the start MAP and the target
    (mmHg, from the run's trajectory), the drug and its concentration (µg/ml), the weight (kg,
    ``None``: not known) and the run's length (s).

    Parameters
    ----------
    summary
        The run's summary (:func:`build_summary`); a ``pressor run``'s ``syringe`` and ``dose``
        records name the drug and the weight.
    result
        The loop's result (its trajectory gives the start MAP and the target), or ``None``.
    drug
        The design's :class:`pressor.contracts.drug.DrugBinding` when the summary names none
        (``pressor sil``); ``None``: the shipped designs' phenylephrine at 100 µg/ml.
    weight_kg
        The patient's weight (kg), if known.
    """
    from pressor.contracts.drug import DEFAULT_BINDING

    ctx: dict[str, Any] = {}
    syringe = summary.get("syringe")
    if syringe is not None:
        ctx["drug"], ctx["concentration_ug_ml"] = syringe["drug"], syringe["concentration_ug_ml"]
    else:
        binding = DEFAULT_BINDING if drug is None else drug
        ctx["drug"], ctx["concentration_ug_ml"] = binding.name, binding.concentration_ug_ml
    dose = summary.get("dose") or {}
    ctx["weight_kg"] = dose.get("weight_kg", weight_kg)
    ctx["duration_s"] = summary.get("ticks", 0) / summary.get("rate_hz", 10.0)
    tr = getattr(result, "trajectory", None)
    if tr is not None and len(tr["map_mmhg"]):
        y = np.asarray(tr["map_mmhg"], dtype=float)
        r = np.asarray(tr["target_mmhg"], dtype=float)
        fy, fr = np.flatnonzero(np.isfinite(y)), np.flatnonzero(np.isfinite(r))
        ctx["start_map_mmhg"] = float(y[fy[0]]) if fy.size else None
        ctx["target_mmhg"] = float(r[fr[0]]) if fr.size else None
        ctx["final_target_mmhg"] = float(r[fr[-1]]) if fr.size else None
        ctx["target_changes"] = int(np.count_nonzero(np.diff(r[fr]))) if fr.size else 0
    return ctx


def _describe_patient(ctx: dict[str, Any]) -> str | None:
    """``start MAP 60.0 mmHg, target 80.0 mmHg (+20.0 mmHg)``, or ``None`` when not known."""
    y0, r0 = ctx.get("start_map_mmhg"), ctx.get("target_mmhg")
    if y0 is None and r0 is None:
        return None
    parts = ["start MAP " + ("not measured" if y0 is None else f"{y0:.1f} mmHg")]
    if r0 is None:
        parts.append("no target")
    else:
        step = "" if y0 is None else f" ({'+' if r0 >= y0 else '-'}{abs(r0 - y0):.1f} mmHg)"
        parts.append(f"target {r0:.1f} mmHg{step}")
        if ctx.get("target_changes"):
            parts.append(
                f"changed {ctx['target_changes']} time(s), last to {ctx['final_target_mmhg']:.1f}"
                " mmHg"
            )
    return "patient: " + ", ".join(parts)


def _describe_infusion(metrics: dict[str, Any], ctx: dict[str, Any]) -> list[str]:
    """The drug line and the infusion line: mean and peak rate in ml/h and µg/kg/min, the total in
    ml and mg; per kg at :data:`REFERENCE_WEIGHT_KG` (said so) when the weight is not known."""
    from pressor.contracts.drug import dose_ug_kg_min

    c, w = ctx["concentration_ug_ml"], ctx.get("weight_kg")
    lines = [f"drug: {ctx['drug']} {c:g} µg/ml"]
    if w is None:
        lines[0] += (
            f"; patient weight not known: per-kg doses at a {REFERENCE_WEIGHT_KG:g} kg"
            " reference weight"
        )
        w = REFERENCE_WEIGHT_KG
    else:
        lines[0] += f"; patient weight {w:g} kg"
    total, peak, dur = metrics.get("drug_total_ml"), metrics.get("max_rate_ml_h"), ctx["duration_s"]
    if total is None or peak is None or not dur:
        return lines

    def rate(ml_h: float) -> str:
        return f"{format_number(ml_h, 1)} ml/h = {_dose(dose_ug_kg_min(ml_h, c, w))} µg/kg/min"

    mean = total * 3600.0 / dur
    lines.append(
        f"infusion: mean {rate(mean)}, peak {rate(peak)}; total {format_number(total, 2)} ml"
        f" = {_dose(total * c / 1000.0)} mg"
    )
    return lines


def print_summary(
    summary: dict[str, Any],
    timing: dict[str, Any],
    out: Any = None,
    context: dict[str, Any] | None = None,
    sched_advise: bool = True,
) -> None:
    """The summary for a person (figures named in words with their units, faults in words, nulls
    explained) to ``out`` (default stdout). The JSON summary keeps the names of docs/METRICS.md.

    Parameters
    ----------
    summary
        The run's summary (:func:`build_summary`).
    timing
        The loop timing (µs): ``exec_p50_us`` ... ``skipped_periods``.
    out
        Where to print (default stdout).
    context
        :func:`run_context` (start MAP, target, drug, weight, length); ``None``: the shipped
        designs' drug, no start MAP or target line.
    sched_advise
        Whether the scheduling envelope's faults are advisory (``--sched-faults advise``).
    """
    out = sys.stdout if out is None else out
    ctx = run_context(summary) if context is None else context
    schedule = f", schedule {summary['schedule']}" if "schedule" in summary else ""
    seconds = f" ({ctx['duration_s']:g} s)" if ctx.get("duration_s") else ""
    print(
        f"run: controller {summary.get('controller')}{schedule}, scenario"
        f" {summary.get('scenario', 'not known')}, patient seed"
        f" {summary.get('patient_seed', 'not known')}; {summary['ticks']} ticks{seconds},"
        f" {summary['ended']}",
        file=out,
    )
    patient = _describe_patient(ctx)
    if patient is not None:
        print(patient, file=out)
    if "target" in summary:  # pressor run
        print(describe_target(summary["target"]), file=out)
    metrics = summary["metrics"]
    for line in _describe_infusion(metrics, ctx):
        print(line, file=out)
    if "dose" in summary:  # pressor run: the drug library
        d = summary["dose"]
        print(
            f"dose limits ({d['unit'].replace('ug', 'µg')}): hard {d['hard_max']:g}, soft {d['soft_max']:g}"
            + (f"; {d['detections']}" if d["detections"] else ""),
            file=out,
        )
    print("metrics (defined in docs/METRICS.md):", file=out)
    if "error" in metrics:
        print(f"  {metrics['error']}", file=out)
    width = max(len(lab.name) for lab in LABELS.values())
    for k, v in metrics.items():
        if k in ("disturbances", "error"):
            continue
        text = _fmt(v, k)
        if v is None:
            text = f"not measured: {null_reason(k, metrics)}"
        print(f"  {_name(k):<{width}}  {text}", file=out)
    events = metrics.get("disturbances")
    if events is None and "disturbances" in metrics:
        print("  disturbances: not known (the device's scenario is not known)", file=out)
    for d in events or []:
        rec = (
            "not measured: " + null_reason("recovery_s")
            if d["recovery_s"] is None
            else (_fmt(d["recovery_s"], "recovery_s"))
        )
        print(
            f"  {d['kind']} at {d['start_s']:g} s: peak deviation"
            f" {_fmt(d['peak_deviation_mmhg'], 'peak_deviation_mmhg')},"
            f" recovery {rec},"
            f" IAE {_fmt(d['iae_mmhg_s'], 'iae_mmhg_s')}",
            file=out,
        )
    sup = summary["supervisor"]
    ticks = max(1, summary["ticks"])
    states = ", ".join(
        f"{_STATE_WORDS.get(k, k)} ({k}) "
        + ("the whole run" if v == ticks else f"{format_number(100.0 * v / ticks, 1)} % of the run")
        for k, v in sup["ticks_in_state"].items()
        if v
    )
    print(f"supervisor: {states or 'no ticks'}", file=out)
    alarms = describe_detections(sup["detections"], sched_advise)
    if alarms:
        print("faults raised:", file=out)
        for line in alarms:
            print(f"  {line}", file=out)
    else:
        print("faults raised: none", file=out)
    print(
        "loop timing (µs): controller step median {exec_p50_us:.1f}, 99th percentile"
        " {exec_p99_us:.1f}, max {exec_max_us:.1f}; lateness median {lateness_p50_us:.1f},"
        " 99th percentile {lateness_p99_us:.1f}, max {lateness_max_us:.1f}; overruns {overruns};"
        " skipped periods {skipped_periods}".format(**timing),
        file=out,
    )
    errs = [f"{k.replace('_', ' ')} {v}" for k, v in summary["link_errors"].items() if v]
    print(f"link: {'clean' if not errs else ', '.join(errs)}", file=out)
    dropped = [f"{k} {v}" for k, v in summary["link_dropped"].items() if v]
    if dropped:
        print(f"link dropped: {', '.join(dropped)}", file=out)
    if summary.get("faults"):
        print_fault_table(summary["faults"], summary["commands_out_of_range"], out)


def print_fault_table(faults: list[dict[str, Any]], out_of_range: int, out: Any = None) -> None:
    """The per-fault table: detection latency (ticks, bound), safe-state time, re-entry step."""
    out = sys.stdout if out is None else out
    print(
        f"{'fault':<18} {'start':>6} {'detect':>6} {'lat':>4} {'bound':>5} {'ok':>3}"
        f" {'safe_s':>7} {'reentry_ml_h':>12}  detected as",
        file=out,
    )
    for f in faults:
        if not f["applicable"]:
            print(f"{f['kind']:<18} {f['start_tick']:>6}  n/a (controller not scheduled)", file=out)
            continue
        ok = {True: "yes", False: "NO", None: "-"}[f["within_bound"]]
        print(
            f"{f['kind']:<18} {f['start_tick']:>6} {_fmt(f['detected_tick']):>6}"
            f" {_fmt(f['latency_ticks']):>4} {_fmt(f['bound_ticks']):>5} {ok:>3}"
            f" {f['safe_state_s']:>7.1f} {f['max_reentry_step_ml_h']:>12.3f}"
            f"  {','.join(f['detected_as']) or '-'}",
            file=out,
        )
    print(f"commands out of [0, max]: {out_of_range}", file=out)
