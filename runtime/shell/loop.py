"""The fixed-rate loop: the shell around the controller step (PX4 module style).

Each tick: read the newest sample, target and scheduling parameters from the link, hand them with
the pump status and the link's health to the closed-loop core (:mod:`pressor.runtime.core.closed_loop`, the
same core the in-process trial runs), send the command, record. The loop holds only link I/O,
recording and its own timing (:class:`~pressor.runtime.shell.timing.TimingStats`).

Two ways to keep time, lockstep (default in ``pressor sil``) and real time (``--realtime``), are
the drivers of :mod:`pressor.runtime.shell.drivers`; :class:`Loop` runs them
(:meth:`Loop.run_lockstep`, :meth:`Loop.run_realtime`) and holds the per-tick work and the
run's account.

Execution time = wall time from release (sample decoded, or deadline reached) to the command
written; recording comes after. Real-time ticks run slower than lockstep ones: after a period
asleep the caches are cold (figures: docs/notes/benchmarks.md, "Design measurements"). A stop signal
(:mod:`pressor.runtime.shell.interrupt`) ends either loop at a tick boundary after a safe-rate command.
"""

from __future__ import annotations

import math
from contextlib import suppress
from typing import Any, Protocol

from pressor.contracts.controller import Controller
from pressor.link import (
    MODE_AUTO,
    MODE_MANUAL,
    MODE_SAFE,
    MODE_STOP,
    STATE_FAULT,
    STATE_FINISHED,
    STATE_RUNNING,
    LinkError,
    RuntimeSession,
    TickInputs,
)
from pressor.runtime.core.closed_loop import ClosedLoopCore, LinkHealth
from pressor.runtime.core.events import EventLog
from pressor.runtime.core.scheduling import ScheduleSource
from pressor.runtime.core.supervisor import AckOutcome, Supervisor
from pressor.runtime.core.supervisor_config import DOSE_FAULTS, State
from pressor.runtime.record.recorder import Recorder
from pressor.runtime.shell.boundary import Boundary
from pressor.runtime.shell.clock import MonotonicClock, perf_counter_s
from pressor.runtime.shell.drivers import DeviceStalled, lockstep, realtime
from pressor.runtime.shell.interrupt import signal_name
from pressor.runtime.shell.timing import TimingStats
from pressor.runtime.shell.trajectory import LoopResult, Trajectory

#: re-exported: where the runtime's callers have always imported it from
__all__ = ["DeviceStalled", "Loop", "TickTarget"]

_NAN = math.nan
_DOSE_FAULTS = int(DOSE_FAULTS)
#: the INFUSION_COMMAND mode of each state (the others: SAFE, the supervisor's fallback)
_MODES = {State.AUTO: MODE_AUTO, State.STOPPED: MODE_STOP, State.MANUAL: MODE_MANUAL}


class TickTarget(Protocol):
    """What the loop asks each tick of the runtime's own target (an input given to the loop, not a
    subclass of it: :class:`pressor.runtime.inputs.target_source.TargetSource`)."""

    def apply(self, inp: TickInputs, recorder: Any = None) -> TickInputs: ...
    def take_acks(self) -> list[str]: ...
    def take_commands(self) -> list[tuple[str, float, str]]: ...
    def log_ack(
        self, outcome: AckOutcome, sources: list[str], tick: int, t: float, recorder: Any = None
    ) -> None: ...
    def log_command(
        self, outcome: AckOutcome, command: tuple[str, float, str], tick: int, t: float,
        recorder: Any = None,
    ) -> None: ...  # fmt: skip


class Loop:
    """The runtime loop over a connected :class:`~link.RuntimeSession`.

    Parameters
    ----------
    controller
        Any :class:`~pressor.contracts.controller.Controller` (stepped once per tick).
    supervisor
        The safety supervisor (its config's period must match the controller's).
    endpoint
        Runtime-side endpoint, handshake done.
    recorder
        Optional rerun recorder (closed by the caller).
    heartbeat_every
        Ticks between runtime heartbeats (about 1 s of run time at the default).
    history_ticks
        Keep only the last this-many ticks of the trajectory (a ring: bounded memory for soak
        runs); ``None`` keeps every tick.
    on_tick
        Called after every tick with ``(tick, state, fault bits, command ml/h)`` (e.g. a
        :class:`pressor.contracts.faults.FaultScorer`'s ``update``).
    status
        Called after every tick with its :class:`pressor.runtime.core.closed_loop.TickRecord`
        (:class:`pressor.runtime.shell.status.StatusLine`: a line for whoever watches), or None.
    schedule
        The scheduling source the core steps the controller on
        (:func:`pressor.runtime.estimation.sources.make_schedule`); default the oracle.
    prog
        Program name in front of the controller-fault lines on stderr (:mod:`pressor.runtime.core.events`).
    ack_input
        Whether the clinician can acknowledge (``pressor run --target-stdin`` or
        ``--target-file``): what those lines say ends a controller fault's hold.
    target
        The runtime's own target (``pressor run --target-*``), or ``None`` (the device's): applied
        to every tick's inputs before the core steps, silent ticks included, its changes logged
        to the recorder; the acknowledgements it read are handed to the supervisor for the tick
        and their outcome logged.
    boundary
        The checks of each tick's inputs and of the record writers before the core
        (:class:`pressor.runtime.shell.boundary.Boundary`); default: the sample time, the ``.tlog``.
    on_stop
        The last command a stop signal sends (``--on-stop``): ``held`` (the safe command:
        :meth:`safe_rate_ml_h`, mode SAFE) or ``zero`` (0 ml/h, mode STOP).
    """

    def __init__(
        self,
        controller: Controller,
        supervisor: Supervisor,
        endpoint: RuntimeSession,
        recorder: Recorder | None = None,
        heartbeat_every: int = 10,
        history_ticks: int | None = None,
        on_tick: Any = None,
        status: Any = None,
        schedule: ScheduleSource | None = None,
        prog: str = "pressor",
        ack_input: bool = False,
        target: TickTarget | None = None,
        boundary: Boundary | None = None,
        on_stop: str = "held",
    ) -> None:
        self.core = ClosedLoopCore(controller, supervisor, schedule)
        self.on_stop = on_stop
        self.sup = supervisor
        self.ep = endpoint
        self.recorder = recorder
        self.target = target
        if recorder is not None:
            recorder.use_controller(controller)
        self.period_s = float(controller.sample_period_s)
        self.boundary = boundary or Boundary(
            self.period_s, supervisor.config.max_rate_ml_h, [("tlog", endpoint.tlog)], prog
        )
        self.timing = TimingStats(self.period_s)
        self.trajectory = (
            Trajectory(period_s=self.period_s)
            if history_ticks is None
            else Trajectory(int(history_ticks), ring=True, period_s=self.period_s)
        )
        self.on_tick = on_tick
        self.status = status
        self.heartbeat_every = max(1, int(heartbeat_every))
        self.ticks_in_state = [0] * len(State)
        self.events = EventLog(recorder, prog, ack_input=ack_input)
        self.out_of_range = 0
        self._count = 0
        self._wall0 = perf_counter_s()
        self._link_errors_seen = 0
        self._stop_signal: int | None = None
        self._last_command = 0.0  # ml/h
        self._last_tick = -1  # the newest tick handled
        self._error: BaseException | None = None

    # ------------------------------------------------------------------ one tick
    def tick(
        self,
        inp: TickInputs,
        now_s: float,
        release_wall_s: float,
        *,
        sample_age_s: float = 0.0,
        link_silence_s: float = 0.0,
        lateness_s: float = 0.0,
        skipped: int = 0,
        send: bool = True,
        boundary_faults: int = 0,
    ) -> float:
        """Supervise, step, send and record one tick; return the command (ml/h).

        ``send=False`` (a silent tick of a stalled link, see the module docstring) skips the
        link and records MAP as NaN (no sample arrived for this tick). With a ``target``, ``inp``
        carries the runtime's target in place of the device's, and the clinician's
        acknowledgement, if one came, is judged at this tick. ``boundary_faults``: what the
        driver's checks of the tick's inputs found (``SAMPLE_TIME``); the record writers' and
        a mid-run hello's faults are added here (:mod:`pressor.runtime.shell.boundary`).
        """
        target = self.target
        acks: list[str] = []
        said: tuple[str, float, str] | None = None
        bound = self.boundary
        if target is not None:
            inp = target.apply(inp, self.recorder)
            acks = target.take_acks()
            if acks:
                self.sup.acknowledge()
            commands = target.take_commands()
            if commands:  # several within one tick: the last one counts
                said = commands[-1]
                self.sup.command(said[0], said[1])
        else:
            boundary_faults |= bound.device_target(inp)
        ep = self.ep
        boundary_faults |= bound.tick_faults(inp.tick, inp.sim_time_s, self.recorder)
        if ep.hello_changes:  # refused on the wire already; the run keeps its first terms
            changed = bound.device_changed(
                ep.take_hello_changes(), inp.tick, inp.sim_time_s, self.recorder
            )
            self.sup.latch(changed)
            boundary_faults |= changed
        pump = ep.pump_status if send else None
        if pump is not None and pump.tick == inp.tick:
            self.trajectory.delivered(pump.tick, bound.delivered(pump.delivered_ml_h))
        health = LinkHealth(sample_age_s, link_silence_s, self.link_errors(), boundary_faults)
        rec = self.core.step(inp, now_s, pump, health)
        out = rec.supervisor
        command, state = out.command_ml_h, out.state
        if send:
            if self._count % self.heartbeat_every == 0:
                ep.send_heartbeat(inp.tick, STATE_RUNNING, flush=False)
            ep.send_command(inp.tick, command, _MODES.get(state, MODE_SAFE))
        exec_s = perf_counter_s() - release_wall_s
        self._last_command = command
        self._last_tick = inp.tick
        self._count += 1
        self.timing.record(exec_s, lateness_s, skipped)
        if not 0.0 <= command <= self.sup.config.max_rate_ml_h:  # by construction never; counted
            self.out_of_range += 1
        self.ticks_in_state[state] += 1
        map_rec = inp.map_mmhg if send else _NAN
        self.trajectory.append(rec, map_rec)
        self.events.log(rec)
        guard = self.sup.dose_guard
        if guard is not None and out.new_faults & _DOSE_FAULTS and guard.reason:
            self.events.dose(rec, guard.reason)  # the limit and, past 10 min, the shortfall
        if self.recorder is not None:
            c = ep.counters
            bad = c.bad_crc + c.refused_unsigned + c.refused_bad_signature + c.resyncs
            self.recorder.record_tick(rec, map_rec, ep.pump_status, bad, exec_s, lateness_s)
        if self.on_tick is not None:
            self.on_tick(inp.tick, int(state), int(out.faults), command)
        if self.status is not None:
            self.status(rec)
        if acks and target is not None and self.sup.last_ack is not None:
            target.log_ack(self.sup.last_ack, acks, inp.tick, inp.sim_time_s, self.recorder)
        if said is not None and target is not None and self.sup.last_command is not None:
            target.log_command(self.sup.last_command, said, inp.tick, inp.sim_time_s, self.recorder)
        return command

    def link_errors(self) -> int:
        """Frames the link layer discarded since the previous tick."""
        total = self.ep.counters.discarded()
        new = total - self._link_errors_seen
        self._link_errors_seen = total
        return new

    # ------------------------------------------------------------------ drivers
    def run_lockstep(self, n_ticks: int, stall_timeout_s: float = 10.0) -> LoopResult:
        """Answer the device's samples one by one until ``n_ticks`` are answered (0: until it ends)
        (:func:`pressor.runtime.shell.drivers.lockstep`).

        On any exit the pump is left with a command: a stop signal and a failure (the device
        stalled, an internal error) send the safe command first (:meth:`_fail_safe`); a failure
        then ends the run with :attr:`LoopResult.error` set (a ``BaseException`` that is not an
        ``Exception`` is raised again after the safe command).
        """
        try:
            return lockstep(self, n_ticks, stall_timeout_s)
        except Exception as exc:
            return self._failed(exc)
        except BaseException as exc:
            self._fail_safe(exc)
            raise

    def run_realtime(
        self,
        n_ticks: int,
        first_sample_timeout_s: float = 10.0,
        clock: MonotonicClock | None = None,
    ) -> LoopResult:
        """Run on the wall clock with absolute deadlines for ``n_ticks`` periods (0: until the end)
        (:func:`pressor.runtime.shell.drivers.realtime`).

        Each period answers the newest sample received; stale samples and link silence feed the
        supervisor's watchdogs. Exits as :meth:`run_lockstep` does (the safe command first).
        """
        try:
            return realtime(self, n_ticks, first_sample_timeout_s, clock)
        except Exception as exc:
            return self._failed(exc)
        except BaseException as exc:
            self._fail_safe(exc)
            raise

    def start_wall_clock(self) -> None:
        """The run starts now (its ``wall_s``): a driver calls it as its first tick nears."""
        self._wall0 = perf_counter_s()

    # ------------------------------------------------------------------ ending
    def safe_rate_ml_h(self) -> float:
        """The documented safe command (ml/h): the supervisor's safe rate, else the last
        command, held."""
        safe = self.sup.config.safe_rate_ml_h
        return self._last_command if safe is None else safe

    def stop_safe(self, last: TickInputs | None, signum: int) -> str:
        """Stop on a signal: command the safe rate (:meth:`safe_rate_ml_h`, mode SAFE), or with
        ``on_stop="zero"`` 0 ml/h (mode STOP), for the tick after ``last``; return the ``ended``
        text."""
        zero = self.on_stop == "zero"
        with suppress(LinkError, OSError):
            self.ep.send_command(
                0 if last is None else last.tick + 1,
                0.0 if zero else self.safe_rate_ml_h(),
                MODE_STOP if zero else MODE_SAFE,
            )
        self._stop_signal = signum
        return f"interrupted by {signal_name(signum)}"

    def _fail_safe(self, exc: BaseException) -> None:
        """The run fails (``exc``): send the safe command for the next tick and a heartbeat
        FAULT before anything else, so the pump is never left on a command nobody chose."""
        self._error = exc
        with suppress(LinkError, OSError):
            self.ep.send_command(self._last_tick + 1, self.safe_rate_ml_h(), MODE_SAFE)
            self.ep.send_heartbeat(max(self._last_tick, 0), STATE_FAULT)

    def _failed(self, exc: Exception) -> LoopResult:
        """The run's account after a failure: the safe command sent, ``error`` set."""
        self._fail_safe(exc)
        result = self.result(f"failed: {exc}")
        result.error = exc
        return result

    def finish(self) -> None:
        """Tell the device the run is over (a FINISHED heartbeat)."""
        with suppress(LinkError, OSError):
            self.ep.send_heartbeat(self.trajectory.last_tick() or 0, STATE_FINISHED)

    def result(self, ended: str) -> LoopResult:
        """Collect the run's account."""
        return LoopResult(
            trajectory=self.trajectory.arrays(),
            timing=self.timing.summary(),
            link=self.ep.counters.as_dict(),
            detections=dict(self.sup.detections),
            ticks_in_state={  # the clinician's states only when they occurred
                s.name: self.ticks_in_state[s]
                for s in State
                if self.ticks_in_state[s] or s not in (State.STOPPED, State.MANUAL)
            },
            transitions=list(self.events.transitions),
            controller_faults=list(self.events.controller_faults),
            commands_out_of_range=self.out_of_range,
            ended=ended,
            wall_s=perf_counter_s() - self._wall0,
            stop_signal=self._stop_signal,
            boundary=self.boundary.summary(),
            kept_bytes=self.trajectory.nbytes,
        )
