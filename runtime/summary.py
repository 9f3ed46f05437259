"""The summary of a runtime run: built from the loop's result, printed, written as JSON.

:func:`build_summary` gives the JSON-ready summary: run identity, the per-run metrics
(:func:`pressor.contracts.metrics.run_metrics`, defined in docs/METRICS.md; with ``pressor sil`` the step
metrics stop at the first disturbance and each hemorrhage or bolus of the scenario gets a
``disturbances`` record; with ``pressor run`` the device's scenario is not known, so those are
null) plus ``commands_out_of_range``, the supervisor's account, the link's error counts
(``link_errors``), what the runtime's end of the link dropped by cause (``link_dropped``, every
cause of :data:`pressor.link.counters.DROP_CAUSES`, documented in docs/PROTOCOL.md) and, when
faults were scheduled, the scored fault list (:func:`pressor.contracts.faults.fault_report`: ``kind``,
``start_tick``, ``detected_tick``, ``latency_ticks`` and its documented bound, ``safe_state_s``,
``max_reentry_step_ml_h``). It holds only values that are functions of the seed (no wall-clock
timing), so two runs give identical files - except the link counts of a run that lost frames
(the device resends on the wall clock); loop timing (p50/p99/max) is printed, written with
``--timing`` and recorded under ``/loop``.

``reachable`` is inferred from the run, since the runtime does not know the patient: false when
the pump sat at its limit for the whole final 10 % of the run with MAP still below the target by
more than the metrics' band (:func:`pressor.contracts.metrics.reachable_band_mmhg`: the settling band of
the run's step, 2 % of it noise-free or 5 mmHg noisy; 5 mmHg without a step).

:func:`finish` prints the summary and writes the ``--summary`` and ``--timing`` files atomically
(:mod:`pressor.plumbing.files`): a failed run leaves earlier files untouched.
"""

from __future__ import annotations

import json
import math
import os
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from pressor.contracts.metrics import reachable_band_mmhg, run_metrics
from pressor.contracts.metrics.labels import LABELS, format_number, format_value, null_reason
from pressor.link.counters import DROP_CAUSES
from pressor.plumbing.files import write_atomic
from pressor.runtime.core.fault_words import describe_detections
from pressor.runtime.inputs.clinician import describe_target
from pressor.runtime.inputs.config import RunConfig
from pressor.runtime.shell.trajectory import held_delivered_ml_h


def replay_command(rrd: Any, environ: Mapping[str, str] | None = None) -> str:
    """The command that replays ``rrd`` on this machine: the native viewer where there is a
    display (``DISPLAY`` or ``WAYLAND_DISPLAY`` set), else the web viewer on localhost (the
    native one fails without a display; docs/VIEWER.md)."""
    env = os.environ if environ is None else environ
    if env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"):
        return f"rerun {rrd}"
    return f"rerun --web-viewer --bind 127.0.0.1 {rrd}  (no display here: open the printed URL)"


def _step_of(
    t: np.ndarray, map_mmhg: np.ndarray, target: np.ndarray
) -> tuple[float | None, float | None]:
    """The target step (time s, size mmHg) as the runtime sees it.

    The first change of the target; or, if the target never changes, the distance from the first
    MAP sample to the target at the first tick (a run that starts ≥ 1 mmHg away from its target,
    like ``paper-tracking`` whose step is at t = 0). ``(None, None)`` otherwise.
    """
    finite = np.isfinite(target)
    if not finite.any():
        return None, None
    i0 = int(np.argmax(finite))
    first = target[i0]
    changed = np.flatnonzero(finite & (target != first))
    if changed.size:
        i = int(changed[0])
        return float(t[i]), float(target[i] - first)
    d = float(first - map_mmhg[i0])
    if math.isfinite(d) and abs(d) >= 1.0:
        return float(t[i0]), d
    return None, None


def _reachable(
    map_mmhg: np.ndarray, target: np.ndarray, cmd: np.ndarray, umax: float, band_mmhg: float
) -> bool:
    n_tail = max(1, int(round(0.1 * cmd.size)))
    at_limit = bool(np.all(cmd[-n_tail:] >= umax * (1.0 - 1e-6)))
    below = np.nanmedian(target[-n_tail:] - map_mmhg[-n_tail:]) > band_mmhg
    return not (at_limit and below)


def build_summary(
    result: Any,
    identity: dict[str, Any],
    max_rate_ml_h: float,
    noisy: bool,
    faults: list[dict[str, Any]] | None = None,
    events: list[tuple[str, float]] | None = None,
) -> dict[str, Any]:
    """The JSON-ready summary of a run (see the module docstring).

    Parameters
    ----------
    result
        The loop's :class:`pressor.runtime.shell.trajectory.LoopResult`. The rate metrics (drug total, max
        rate, time at limit) use the rate the pump reported delivering (its ``delivered_ml_h``).
    identity
        Run identity (controller, scenario, seed, rate, ...), copied into the summary.
    max_rate_ml_h
        The controller's largest command (ml/h).
    noisy
        Whether the monitor adds noise (selects the 5 mmHg settling band).
    faults
        The scored fault list, or ``None`` when no fault was scheduled.
    events
        The scenario's disturbance events ``(kind, start_s)``; ``None`` when not known
        (``pressor run``).
    """
    tr = result.trajectory
    t, y, r, u = tr["sim_time_s"], tr["map_mmhg"], tr["target_mmhg"], tr["command_ml_h"]
    # a sample no monitor gives (inf; NaN is "no value") is no measurement: the supervisor held
    # on it, and the metrics must not average it in (an overshoot of inf %)
    y = np.where(np.isfinite(y), y, np.nan)
    if t.size < 2:
        metrics: dict[str, Any] = {"error": "fewer than 2 ticks: no metrics"}
    else:
        step_t, step_d = _step_of(t, y, r)
        metrics = run_metrics(
            t,
            y,
            r,
            held_delivered_ml_h(tr["delivered_ml_h"]),
            max_rate_ml_h,
            step_time_s=step_t,
            step_mmhg=step_d,
            noisy=noisy,
            reachable=_reachable(y, r, u, max_rate_ml_h, reachable_band_mmhg(step_d, noisy)),
            events=events,
        )
    metrics["commands_out_of_range"] = result.commands_out_of_range
    link = result.link
    extra: dict[str, Any] = {}
    if faults is not None:
        extra["faults"] = faults
    if result.stop_signal is not None:
        extra["interrupted"] = True
    error = getattr(result, "error", None)
    if error is not None:  # the run failed (after the safe command): why
        extra["error"] = f"{type(error).__name__}: {error}"
    extra.update(getattr(result, "boundary", None) or {})  # record errors, sample times, hellos
    # controller failures the supervisor held on (pressor run), only when there were some: the
    # summaries of other runs keep their bytes
    held = {"controller_faults": result.controller_faults} if result.controller_faults else {}
    return {
        **extra,
        "commands_out_of_range": result.commands_out_of_range,
        **identity,
        "ticks": int(t.size),
        "ended": result.ended,
        "metrics": metrics,
        "supervisor": {
            "detections": result.detections,
            "ticks_in_state": result.ticks_in_state,
            "transitions": result.transitions[:100],
            **held,
        },
        "link_errors": {
            k: link[k]
            for k in (
                "bad_crc",
                "seq_gaps",
                "frames_lost",
                "refused_unsigned",
                "refused_bad_signature",
            )
        },
        "link_dropped": {k: link[k] for k in DROP_CAUSES},
    }


#: the weight (kg) doses per kg are given at when the run knows none (a simulation has no weight)
REFERENCE_WEIGHT_KG = 70.0


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


def json_ready(value: Any) -> Any:
    """``value`` with every non-finite float replaced by ``None`` (JSON null: a value that does
    not exist, as for a metric that does not apply), in nested dicts, lists and tuples."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    return value


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write ``data`` to ``path`` as sorted, indented JSON, atomically (a non-finite float is
    written as null, never as the non-JSON ``NaN`` / ``Infinity``)."""
    text = json.dumps(json_ready(data), indent=2, sort_keys=True, allow_nan=False)
    write_atomic(path, text + "\n")


def finish(
    summary: dict[str, Any],
    result: Any,
    config: RunConfig,
    prog: str = "pressor",
    drug: Any = None,
    weight_kg: float | None = None,
) -> int:
    """Print the summary, write the ``--summary`` / ``--timing`` files; return the exit code.

    ``drug`` is the design's :class:`pressor.contracts.drug.DrugBinding` for the printed doses
    when the summary names no syringe (``pressor sil``; ``None``: the shipped designs');
    ``weight_kg`` the patient's weight (kg) for the doses per kg when the run's clinician input
    has none (``pressor sil --weight-kg``).

    Returns
    -------
    int
        128 + the signal number when a signal stopped the run (one line on stderr,
        :mod:`pressor.runtime.shell.interrupt`); else 1 if a command left [0, max] or the controller failed
        (``pressor run``: the supervisor held on it, ``supervisor.controller_faults``; a check
        failed) or the record is incomplete (a writer failed during the run, ``record``, or an
        output file cannot be written: one line), else 0.
    """
    # the run is over and the pump has its last command: the files first (a closed stdout, a
    # reader gone from a pipe, must not cost the record), then the terminal; a file that cannot
    # be written (a full disk) is one line and exit 1, never a traceback
    lost = [f"the {name} stopped: {why}" for name, why in summary.get("record", {}).items()]
    written = []
    if config.summary is not None:
        lost += _write_output("summary", config.summary, summary, written)
    if config.timing is not None:
        status = {
            "loop": result.timing,
            "run_wall_s": result.wall_s,
            "sim_s": summary["ticks"] / summary["rate_hz"],
            "link": result.link,
            "host": result.host,
        }
        lost += _write_output("timing", config.timing, status, written)
    weight = weight_kg if config.clinician is None else config.clinician.weight_kg
    context = run_context(summary, result, drug, weight)
    print_summary(
        summary, result.timing, context=context, sched_advise=config.sched_faults != "hold"
    )
    if result.host and config.cpu_latency_us is not None:  # only what was asked for
        print(f"host: CPU wake-up latency request {result.host['cpu_latency']}")
    for line in written:
        print(line)
    if config.rrd is not None:
        print(f"recording: {config.rrd}\nreplay:    {replay_command(config.rrd)}")
    if result.stop_signal is not None:
        from pressor.runtime.shell.interrupt import exit_code

        print(
            f"{prog}: {result.ended} after {summary['ticks']} ticks; safe rate commanded,"
            " outputs kept",
            file=sys.stderr,
        )
        return exit_code(result.stop_signal)
    failed = summary["supervisor"].get("controller_faults")
    if failed:
        print(
            f"{prog}: the controller failed {len(failed)} time(s), first at tick"
            f" {failed[0]['tick']}: {failed[0]['error']}",
            file=sys.stderr,
        )
    if lost:
        print(f"{prog}: the record is incomplete: {'; '.join(lost)}", file=sys.stderr)
    return 1 if summary["metrics"].get("commands_out_of_range") or failed or lost else 0


def _write_output(name: str, path: Path, data: dict[str, Any], written: list[str]) -> list[str]:
    """Write ``data`` to the ``name`` file ``path`` (its line for the terminal added to
    ``written``); ``[why]`` if it failed."""
    try:
        write_json(path, data)
    except OSError as exc:
        return [f"the {name} {path} cannot be written: {exc.strerror or exc}"]
    written.append(f"{name}: {path}")
    return []
