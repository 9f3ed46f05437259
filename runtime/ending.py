"""How a runtime run ends: the summary it leaves on every exit path, and the command's exit code.

:func:`summarize` builds the summary of a run that reached its end (:mod:`pressor.runtime.summary`,
with the fault report, the runtime's own target, the syringe and the dose); a run that failed
after its first tick or was refused before it keeps its ``--summary`` too
(:func:`write_summary`, :func:`write_failed_summary`), and a record writer that failed only as it
closed is filed in the summary (:func:`late_record_error`). :func:`start_run` hands a starting
command over to the graceful stop (:mod:`pressor.runtime.shell.interrupt`) before it opens a port;
:func:`run_guarded` gives ``pressor run`` and ``pressor sil`` their exit codes.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from pressor.plumbing.usage import USAGE_EXIT, run_command
from pressor.runtime.inputs.clinician import ClinicianInput
from pressor.runtime.inputs.config import RunConfig
from pressor.runtime.shell.interrupt import (
    Interrupted,
    begin_run,
    exit_code,
    stop_on_signals,
    stop_requested,
)
from pressor.runtime.summary import build_summary

if TYPE_CHECKING:
    from pressor.contracts.controller import Controller
    from pressor.link import Hello
    from pressor.runtime.core.supervisor import Supervisor
    from pressor.runtime.inputs.target_source import TargetSource
    from pressor.runtime.shell.trajectory import LoopResult


def summarize(
    result: LoopResult,
    identity: dict[str, Any],
    config: RunConfig,
    controller: Controller,
    clinician: ClinicianInput,
    sup: Supervisor,
    peer: Hello,
    target: TargetSource | None,
    events: list[tuple[str, float]] | None,
    noisy_band: bool,
) -> dict[str, Any]:
    """The run's metric summary, with the fault report when faults were injected and, for
    ``pressor run``, where the target came from, the syringe and the dose."""
    report = None
    if config.fault_specs:
        from pressor.contracts.faults import fault_report
        from pressor.runtime.core.supervisor_config import FAULT_BITS, sched_limits_of

        report = fault_report(
            list(config.fault_specs),
            result.trajectory,
            FAULT_BITS,
            config.period_s,
            scheduled=sched_limits_of(controller)[0] is not None,
        )
    summary = build_summary(
        result,
        identity,
        controller.max_rate_ml_h,
        noisy=noisy_band,
        faults=report,
        events=events,
    )
    if target is not None and not target.own_target:  # pressor sil --clinician-stdin
        record = target.summary()
        summary["clinician"] = {"acks": record["acks"], "commands": record.get("commands", [])}
    if config.clinician is not None:  # pressor run: where the target came from, the syringe
        summary["target"] = {"source": "device"} if target is None else target.summary()
        summary["syringe"] = {
            "drug": clinician.drug,
            "concentration_ug_ml": clinician.concentration_ug_ml,
            "pump_max_ml_h": float(peer.pump_max_ml_h),
        }
        if clinician.dose_limits is not None:
            from pressor.runtime.inputs.dosing import dose_summary

            summary["dose"] = dose_summary(
                result.trajectory["command_ml_h"],
                config.period_s,
                clinician,
                sup.detections,
                result.trajectory["sim_time_s"],  # elapsed time: a skipped stretch is charged
            )
    return summary


def late_record_error(result: LoopResult, name: str, error: str | None) -> None:
    """File a writer failure found only when the writer closed (its last write) in the run's
    record errors, as the loop files the ones it sees (:mod:`pressor.runtime.shell.boundary`)."""
    if error is not None:
        result.boundary.setdefault("record", {}).setdefault(name, error)


def write_summary(path: Any, summary: dict[str, Any]) -> None:
    """Write ``summary`` to ``path`` (JSON); a disk that fails is one line on stderr, not a second
    error on top of the run's own."""
    from pressor.runtime.summary import write_json

    try:
        write_json(path, summary)
    except OSError as exc:
        print(f"pressor: summary {path}: cannot be written: {exc.strerror or exc}", file=sys.stderr)


def write_failed_summary(config: RunConfig, identity: dict[str, Any], exc: Exception) -> None:
    """The summary of a run that ended before its first tick (refused, the link failed): its
    identity, no ticks, and why (``ended``, ``error``)."""
    if config.summary is not None:
        why = f"{type(exc).__name__}: {exc}"
        write_summary(config.summary, {**identity, "ticks": 0, "ended": why, "error": why})


def start_run() -> None:
    """Call before a command opens its port or starts its device: from here a stop signal is a
    graceful stop (:func:`pressor.runtime.shell.interrupt.begin_run`); one that came while the
    command started raises :class:`Interrupted` (``before the run started``: nothing to keep)."""
    begin_run()
    if (stop := stop_requested()) is not None:
        raise Interrupted(stop, "before the run started")


def run_guarded(prog: str, handler: Callable[[Sequence[str]], int], argv: Sequence[str]) -> int:
    """Run a runtime command with its exit codes.

    0 success; 1 the run completed but a check failed, or the device stalled or the link failed,
    or the controller raised under ``pressor sil``
    (:class:`pressor.runtime.core.closed_loop.ControllerError`; ``pressor run`` holds instead,
    :mod:`pressor.runtime.core.supervisor`) (one line on stderr); 2 bad usage or input
    (:func:`pressor.plumbing.usage.run_command`), or the device's hello refused (:class:`link.Refusal`: one
    line, the device was told); 130 / 143 stopped by SIGINT / SIGTERM
    (:mod:`pressor.runtime.shell.interrupt`: the run stops at a tick boundary, commands the safe rate, and
    keeps its outputs).
    """
    from pressor.link import LinkError, Refusal
    from pressor.runtime.core.closed_loop import ControllerError
    from pressor.runtime.shell.loop import DeviceStalled

    def guarded(args: Sequence[str]) -> int:
        with stop_on_signals():
            try:
                return handler(args)
            except Refusal as exc:  # a hello refused, by either end: the other was told why
                print(f"{prog}: {exc}", file=sys.stderr)
                return USAGE_EXIT
            except (DeviceStalled, LinkError, ControllerError) as exc:
                print(f"{prog}: {exc}", file=sys.stderr)
                return 1
            except Interrupted as exc:
                print(f"{prog}: {exc}", file=sys.stderr)
                return exit_code(exc.signum)

    return run_command(prog, guarded, argv)
