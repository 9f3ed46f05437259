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

:func:`finish` prints the summary (:mod:`pressor.runtime.summary.text`: the lines for a person) and
writes the ``--summary`` and ``--timing`` files atomically
(:mod:`pressor.plumbing.files`): a failed run leaves earlier files untouched.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from pressor.contracts.metrics import reachable_band_mmhg, run_metrics
from pressor.link.counters import DROP_CAUSES
from pressor.plumbing.files import write_atomic
from pressor.runtime.inputs.config import RunConfig
from pressor.runtime.shell.trajectory import held_delivered_ml_h
from pressor.runtime.summary.text import (
    print_fault_table,
    print_summary,
    replay_command,
    run_context,
)

__all__ = [
    "build_summary",
    "finish",
    "json_ready",
    "print_fault_table",
    "print_summary",
    "replay_command",
    "run_context",
    "write_json",
]


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
