"""One runtime run on an open port: handshake, controller, supervisor, recorder, loop, summary.

:func:`run_runtime` is the runtime end of ``pressor run`` (a port it opened) and of ``pressor sil``
(the leader of the pty whose follower the device process opened). The record of every run is
kept, the one of a run that went wrong first of all: the ``.tlog`` is written in place and made
durable every 0.5 s (:class:`pressor.link.tlog.TlogWriter`), the ``.rrd`` is moved into place however the
run ended, and a run that fails after its first tick (the loop sent the safe command first) or is
refused before it writes its ``--summary`` (``ended``, ``error``) before the error is raised.
What a run leaves (its summary on every exit path) and the commands' exit codes
(:func:`run_guarded`) are in :mod:`pressor.runtime.ending`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from pressor.runtime.ending import (  # run_guarded, start_run: re-exported, their old home
    late_record_error,
    run_guarded,
    start_run,
    summarize,
    write_failed_summary,
    write_summary,
)
from pressor.runtime.handshake import handshake
from pressor.runtime.inputs.clinician import TARGET_MAX_MMHG, TARGET_MIN_MMHG, ClinicianInput
from pressor.runtime.inputs.config import RunConfig, load_controller, warn_uncautious
from pressor.runtime.shell.boundary import Unwritten
from pressor.runtime.shell.placement import Pinned

if TYPE_CHECKING:  # the stages' types; at run time each stage imports what it needs, when it runs
    from pressor.contracts.controller import Controller
    from pressor.link import Hello, RuntimeSession
    from pressor.runtime.core.supervisor import Supervisor
    from pressor.runtime.inputs.target_source import TargetSource
    from pressor.runtime.record.recorder import Recorder
    from pressor.runtime.shell.trajectory import LoopResult


def run_runtime(
    port: Any,
    config: RunConfig,
    identity: dict[str, Any],
    signing: Any,
    *,
    events: list[tuple[str, float]] | None = None,
    cpus: tuple[int, int] | None = None,
    on_connected: Callable[[], object] | None = None,
    peer_alive: Callable[[], bool] | None = None,
    handshake_timeout_s: float = 30.0,
    on_tick: Callable[[int, int, int, float], object] | None = None,
    before_close: Callable[[Any], object] | None = None,
    noisy_band: bool = True,
) -> tuple[dict[str, Any], Any]:
    """Handshake, build controller/supervisor/recorder, run the loop; return (summary, result).

    The stages, in order: :func:`pressor.runtime.handshake.handshake`, :func:`_build_supervisor`, :func:`_open_recorder`,
    :func:`_run_loop`, :func:`_close_recording`, :func:`pressor.runtime.ending.summarize`.

    Parameters
    ----------
    port
        The open serial port (the runtime end of the link).
    config
        The checked run configuration.
    identity
        Run identity for the summary; the device's hello adds scenario, patient seed and noise.
    signing
        The link's :class:`Signing`, or ``None`` (unsigned).
    events
        The device scenario's disturbance events ``(kind, start_s)``; ``None`` when not known.
    cpus
        ``(loop CPU, device CPU)`` of a pinned lockstep run (:mod:`pressor.runtime.shell.placement`), or
        ``None``; the loop thread runs on the first.
    on_connected
        Called once the handshake succeeded.
    peer_alive
        Polled while waiting for the handshake: a device that died ends the wait at once.
    handshake_timeout_s
        Wall seconds to wait for the device's hello.
    on_tick
        The loop's per-tick callback ``(tick, state, fault bits, command ml/h)``, e.g. a
        :class:`pressor.runtime.shell.progress.TerminalProgress`.
    before_close
        Called with the :class:`pressor.runtime.record.recorder.Recorder` after the loop ended and before
        the recording is closed (``pressor sil`` adds the simulated device's true MAP there).
    noisy_band
        Whether the summary's settling band is the noisy monitor's ±5 mmHg rather than 2 % of the
        step (docs/METRICS.md): the scenario's choice (``pressor sil``: whether its monitor adds
        noise, as in ``pressor trial``), never the device's noise announcement. ``pressor run``
        does not know the scenario and judges a real, measured monitor: ±5 mmHg (2 % of a 20
        mmHg step is 0.4 mmHg, finer than an integer-mmHg monitor reads).

    Returns
    -------
    tuple
        The summary (:func:`pressor.runtime.summary.build_summary`) and the loop's result.
    """
    from pressor.link import RuntimeSession
    from pressor.link.tlog import TlogWriter

    period_s = config.period_s
    controller = load_controller(config.controller, period_s)
    clinician = _clinician_for(config, controller)
    live = None
    if config.view:  # before the handshake: the device waits for it, not the loop
        from pressor.runtime.shell.viewer import open_view

        live = open_view(config.view_port, _prog(config))
    tlog = TlogWriter(config.tlog) if config.tlog is not None else None
    ok = False
    # only the oracle schedules on the device's SCHEDULING_PARAMS: otherwise a device may send
    # none; with the runtime's own target the device's MAP_TARGET is not needed either
    ep = RuntimeSession(
        port,
        signing=signing,
        tlog=tlog,
        require_sched=config.schedule == "oracle",
        require_target=clinician.target_mmhg is None,
    )
    recorder = None
    try:
        try:
            peer = handshake(ep, config, controller, clinician, peer_alive, handshake_timeout_s,
                              on_connected)  # fmt: skip
        except Exception as exc:  # refused, a link error: the record says so, then the error
            write_failed_summary(config, identity, exc)
            raise
        identity = _run_identity(identity, config, peer)
        # said once the run will dose: first doses for a typical patient (not a refused run)
        caution = warn_uncautious(config.controller, config.schedule, _prog(config))
        if caution is not None:  # only then: the summaries of other runs keep their bytes
            identity = {**identity, "caution_warning": caution}
        sup = _build_supervisor(config, controller, clinician, peer)
        recorder = _open_recorder(config, identity, clinician, peer, live)
        unstarted = recorder if isinstance(recorder, Unwritten) else None
        if unstarted is not None:
            recorder = None
        if recorder is not None:
            recorder.plan_markers(_markers(config, events))
            if caution is not None:  # on the clinician's timeline too
                recorder.event(0, 0.0, caution)
        result, target = _run_loop(config, controller, clinician, sup, ep, peer, recorder, cpus,
                                   on_tick, tlog, unstarted)  # fmt: skip
        ep.close()  # the device sees the end at once; the record is written after
        if tlog is not None:
            tlog.close()  # its last write may fail too: the summary says so
            late_record_error(result, "tlog", tlog.error)
        if recorder is not None:
            _close_recording(recorder, result, clinician, before_close)
            late_record_error(result, "recording", recorder.error)
            recorder = None
        summary = summarize(result, identity, config, controller, clinician, sup, peer, target,
                             events, noisy_band)  # fmt: skip
        if result.error is not None:  # the loop failed after the safe command: keep the record
            if config.summary is not None:
                write_summary(config.summary, summary)
            raise result.error
        ok = True
        return summary, result
    finally:
        if recorder is not None:
            recorder.abort()  # kept: the record of a run that went wrong
        ep.close()
        if tlog is not None:
            tlog.close(commit=ok)  # in place and durable on every exit path


def _clinician_for(config: RunConfig, controller: Controller) -> ClinicianInput:
    """The clinician's input: ``pressor run``'s own, or for ``pressor sil`` the loaded design's
    syringe, a baseline's the simulated patient's (``config.syringe``); a device announcing
    another is refused."""
    if config.clinician is not None:
        return config.clinician
    from pressor.contracts.drug import binding_of

    design = config.syringe or binding_of(controller)
    return ClinicianInput(drug=design.name, concentration_ug_ml=design.concentration_ug_ml)


def _run_identity(identity: dict[str, Any], config: RunConfig, peer: Hello) -> dict[str, Any]:
    """The run's identity for the summary, with the schedule (unless the oracle) and what the
    device's hello says: scenario, patient seed, monitor noise."""
    if config.schedule != "oracle":  # oracle summaries keep their pre-schedule bytes
        identity = {**identity, "schedule": config.schedule}
    return {
        **identity,
        "scenario": peer.name,
        "patient_seed": peer.patient_seed,
        "sensor_noise_mmhg": float(peer.sensor_noise_mmhg),
    }


def _build_supervisor(
    config: RunConfig, controller: Controller, clinician: ClinicianInput, peer: Hello
) -> Supervisor:
    """The safety supervisor matched to the controller and the device's monitor noise."""
    from pressor.runtime.core.supervisor import Supervisor
    from pressor.runtime.core.supervisor_config import supervisor_config_for

    return Supervisor(
        supervisor_config_for(
            controller,
            peer.sensor_noise_mmhg,
            sched_action=config.sched_faults,
            stale_after_s=config.sample_age_limit_s,
            dose_limits=clinician.dose_limits,  # pressor run: the drug library's
            pump_max_ml_h=max(float(peer.pump_max_ml_h), controller.max_rate_ml_h),
            # pressor run (a patient on the line) holds on a controller fault until the
            # clinician acknowledges; pressor sil stops with exit 1 (pressor.runtime.core.supervisor)
            controller_faults="latch" if config.clinician is not None else "stop",
        )
    )


def _prog(config: RunConfig) -> str:
    """The command running: ``pressor run`` (with the clinician's input) or ``pressor sil``."""
    return "pressor run" if config.clinician is not None else "pressor sil"


def _open_recorder(
    config: RunConfig,
    identity: dict[str, Any],
    clinician: ClinicianInput,
    peer: Hello,
    live: str | None = None,
) -> Recorder | Unwritten | None:
    """The rerun recorder of ``config.rrd`` and, with ``live`` (a viewer's URL), of the live view
    (labelled with controller, scenario, seed, rate and mode), or ``None`` without either, or an
    :class:`pressor.runtime.shell.boundary.Unwritten` naming why it could not start (the loop
    raises ``RECORD_ERROR`` on it and goes on)."""
    if config.rrd is None and live is None:
        return None
    from pressor.runtime.record.recorder import Recorder

    label = (
        f"{identity['controller']}|{peer.name}|seed{peer.patient_seed}|{config.rate_hz}Hz"
        f"|{config.mode}"
    )
    try:
        return Recorder(
            config.rrd, run_label=label, dose_view=clinician.dose_limits is not None, live=live
        )
    except OSError as exc:  # no room to start it: the run goes on unrecorded (RECORD_ERROR)
        return Unwritten(f"{config.rrd}: not started: {exc.strerror or exc}")


def _markers(
    config: RunConfig, events: list[tuple[str, float]] | None
) -> list[tuple[float, str, str]]:
    """The recording's planned markers (s, kind, text): the scenario's disturbances, the faults."""
    return [(t, "disturbance", f"disturbance: {kind} at {t:g} s") for kind, t in events or ()] + [
        (f.start_s, "fault", f"fault: {f.kind} at {f.start_s:g} s") for f in config.fault_specs
    ]


def _dose(config: RunConfig, clinician: ClinicianInput) -> Any:
    """The syringe and patient a schedule converts doses with: the clinician's syringe and weight;
    without a weight, ``pressor sil``'s simulated patient is the reference adult and ``pressor
    run``'s the lightest adult the drug library admits (the most sensitive per ml/h: the cautious
    side)."""
    from pressor.contracts.drug import REFERENCE_WEIGHT_KG, DoseScale
    from pressor.runtime.inputs.drug_library import WEIGHT_MIN_KG

    weight = clinician.weight_kg
    if weight is None:
        weight = WEIGHT_MIN_KG if config.clinician is not None else REFERENCE_WEIGHT_KG
    return DoseScale(clinician.concentration_ug_ml, weight)


def _run_loop(
    config: RunConfig,
    controller: Controller,
    clinician: ClinicianInput,
    sup: Supervisor,
    ep: RuntimeSession,
    peer: Hello,
    recorder: Recorder | None,
    cpus: tuple[int, int] | None,
    on_tick: Callable[[int, int, int, float], object] | None,
    tlog: Any = None,
    unstarted: Unwritten | None = None,
) -> tuple[LoopResult, TargetSource | None]:
    """Run the fixed-rate loop (real time, or lockstep pinned to ``cpus[0]``) under the CPU
    wake-up latency request; return (the loop's result, the runtime's own target or ``None``)."""
    from pressor.runtime.estimation.sources import make_schedule
    from pressor.runtime.inputs.target_source import TargetSource
    from pressor.runtime.shell.boundary import Boundary
    from pressor.runtime.shell.cpu_latency import CpuLatencyRequest
    from pressor.runtime.shell.loop import Loop

    loop_kw: dict[str, Any] = {
        "recorder": recorder,
        "heartbeat_every": round(config.rate_hz),
        "on_tick": on_tick,
        "schedule": make_schedule(
            config.schedule, config.period_s, controller, _dose(config, clinician)
        ),
        "prog": _prog(config),
        "ack_input": clinician.target_stdin or clinician.target_file is not None,
    }
    # the runtime's own target, in place of the device's (pressor.runtime.inputs.target_source)
    target = (
        None
        if clinician.target_mmhg is None
        else TargetSource(clinician, max_rate_ml_h=controller.max_rate_ml_h)
    )
    if target is None and config.clinician_stdin:  # pressor sil: the clinician's commands only
        target = TargetSource(
            ClinicianInput(target_stdin=True),
            prog=loop_kw["prog"],
            max_rate_ml_h=controller.max_rate_ml_h,
            own_target=False,
        )
        loop_kw["ack_input"] = True
    loop_kw["on_stop"] = config.on_stop
    if config.status_every_s is not None and (config.clinician is not None or config.realtime):
        from pressor.runtime.shell.status import StatusLine

        weight = clinician.weight_kg if config.clinician is not None else None
        loop_kw["status"] = StatusLine(
            loop_kw["prog"],
            config.period_s,
            clinician.concentration_ug_ml,
            weight,
            interval_s=config.status_every_s,
        )
    loop_kw["boundary"] = Boundary(
        config.period_s,
        sup.config.pump_max_ml_h or controller.max_rate_ml_h,
        [("tlog", tlog), ("recording", recorder or unstarted)],
        loop_kw["prog"],
        # pressor run: the device's target is bound as the clinician's (pressor sil's device is
        # the simulator, whose targets the in-process trial takes unbounded too)
        target_limits=None if config.clinician is None else (TARGET_MIN_MMHG, TARGET_MAX_MMHG),
    )
    loop = Loop(controller, sup, ep, target=target, **loop_kw)
    with CpuLatencyRequest(config.cpu_latency_us) as wake:
        if config.realtime:
            result = loop.run_realtime(peer.n_ticks if peer.n_ticks else config.ticks)
        else:
            n = config.ticks or peer.n_ticks
            with Pinned(None if cpus is None else cpus[0]):  # rerun's threads exist already
                result = loop.run_lockstep(n, stall_timeout_s=config.stall_timeout_s)
    result.host = {"cpu_latency": wake.status, "cpus": cpus}
    return result, target


def _close_recording(
    recorder: Recorder,
    result: LoopResult,
    clinician: ClinicianInput,
    before_close: Callable[[Any], object] | None,
) -> None:
    """Finish the recording: the caller's additions (``before_close``), the dose series when a
    drug library limits the dose, then close it (moved into place)."""
    if before_close is not None:
        before_close(recorder)
    if clinician.dose_limits is not None:
        from pressor.runtime.inputs.dosing import log_dose_series

        log_dose_series(recorder, result.trajectory, clinician)
    recorder.close()


__all__ = ["run_runtime", "run_guarded", "start_run"]
