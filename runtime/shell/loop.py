"""The fixed-rate loop: the shell around the controller step (PX4 module style).

Each tick: read the newest sample, target and scheduling parameters from the link, hand them with
the pump status and the link's health to the closed-loop core (:mod:`pressor.runtime.core.closed_loop`, the
same core the in-process trial runs), send the command, record. The loop holds only link I/O,
recording and its own timing (:class:`~pressor.runtime.shell.timing.TimingStats`).

Two ways to keep time (injected clocks, :mod:`pressor.runtime.shell.clock`):

Lockstep (default in ``pressor sil``)
    The device sends tick k's sample and waits for tick k's command (PX4 SITL style); the
    :class:`~pressor.runtime.shell.clock.VirtualClock` follows the sample's sim time, in the in-process
    simulator's order, so a clean serial run reproduces it sample for sample. A device silent for
    ``stall_timeout_s`` of *wall* time ends the run (:class:`DeviceStalled`) rather than a link
    loss, which would make the trajectory depend on host load.

    Link stalls in virtual time: a stalled link is a device that keeps simulating without
    exchanging frames, so the next sample is tick k > last + 1. The loop runs the silent ticks
    last+1 … k−1 through the supervisor on the virtual clock (sample age and link silence growing
    one period per tick), recording them with MAP NaN and sending nothing, so STALE_SAMPLE (HOLD)
    and LINK_LOSS (FAILSAFE) fall on exactly the ticks a wall-clock runtime would log them.

Real time (``--realtime``)
    Ticks are released at absolute deadlines ``t0 + k·Ts``
    (:class:`~pressor.runtime.shell.clock.MonotonicClock`); the newest sample is answered, sample age and
    link silence are wall-clock (real watchdogs), and lateness and skipped periods are counted.

Execution time = wall time from release (sample decoded, or deadline reached) to the command
written; recording comes after. Real-time ticks run slower than lockstep ones: after a period
asleep the caches are cold (figures: docs/notes/benchmarks.md, "Design measurements"). A stop signal
(:mod:`pressor.runtime.shell.interrupt`) ends either loop at a tick boundary after a safe-rate command.
"""

from __future__ import annotations

import math
from contextlib import suppress
from dataclasses import replace
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
    LinkClosedError,
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
from pressor.runtime.shell.clock import (
    MonotonicClock,
    PeriodicSchedule,
    VirtualClock,
    perf_counter_s,
)
from pressor.runtime.shell.interrupt import signal_name, stop_requested
from pressor.runtime.shell.timing import TimingStats
from pressor.runtime.shell.trajectory import LoopResult, Trajectory

_NAN = math.nan
_DOSE_FAULTS = int(DOSE_FAULTS)
#: the INFUSION_COMMAND mode of each state (the others: SAFE, the supervisor's fallback)
_MODES = {State.AUTO: MODE_AUTO, State.STOPPED: MODE_STOP, State.MANUAL: MODE_MANUAL}


class DeviceStalled(RuntimeError):
    """The device sent no sample for ``stall_timeout_s`` (wall clock) in lockstep."""


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
        health = LinkHealth(sample_age_s, link_silence_s, self._link_errors(), boundary_faults)
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
        if acks and target is not None and self.sup.last_ack is not None:
            target.log_ack(self.sup.last_ack, acks, inp.tick, inp.sim_time_s, self.recorder)
        if said is not None and target is not None and self.sup.last_command is not None:
            target.log_command(self.sup.last_command, said, inp.tick, inp.sim_time_s, self.recorder)
        return command

    def _link_errors(self) -> int:
        """Frames the link layer discarded since the previous tick."""
        total = self.ep.counters.discarded()
        new = total - self._link_errors_seen
        self._link_errors_seen = total
        return new

    # ------------------------------------------------------------------ drivers
    def run_lockstep(self, n_ticks: int, stall_timeout_s: float = 10.0) -> LoopResult:
        """Answer the device's samples one by one until ``n_ticks`` are answered (0: until it ends).

        On any exit the pump is left with a command: a stop signal and a failure (the device
        stalled, an internal error) send the safe command first (:meth:`_fail_safe`); a failure
        then ends the run with :attr:`LoopResult.error` set (a ``BaseException`` that is not an
        ``Exception`` is raised again after the safe command).
        """
        try:
            return self._lockstep(n_ticks, stall_timeout_s)
        except Exception as exc:
            return self._failed(exc)
        except BaseException as exc:
            self._fail_safe(exc)
            raise

    def _lockstep(self, n_ticks: int, stall_timeout_s: float) -> LoopResult:
        clock = VirtualClock()
        ep = self.ep
        self._wall0 = perf_counter_s()
        self._link_errors()  # what the handshake saw is not a fault of tick 0
        answered = 0
        last: TickInputs | None = None
        ended = "completed"
        poll_s = min(0.5, stall_timeout_s)
        while n_ticks == 0 or answered < n_ticks:
            waited = 0.0
            inp = None
            try:
                while inp is None:
                    if (stop := stop_requested()) is not None:
                        break
                    inp = ep.wait_for_sample(poll_s)
                    if inp is None:
                        if ep.peer_heartbeat is not None and ep.peer_heartbeat[1] == STATE_FINISHED:
                            break
                        waited += poll_s
                        if waited >= stall_timeout_s:
                            raise DeviceStalled(
                                f"device sent no sample for {stall_timeout_s} s after"
                                f" {answered} ticks"
                            )
            except LinkClosedError:
                ended = "device closed the link"
                break
            if inp is None:  # the device finished, or a stop signal came
                ended = "device finished" if stop is None else self._stop_safe(last, stop)
                break
            if last is not None and inp.tick > last.tick + 1:
                self._silent_ticks(last, inp.tick, clock)
                answered += inp.tick - last.tick - 1
            release = perf_counter_s()
            inp, bad_time = self.boundary.sample_time(inp)
            clock.advance_to(max(inp.sim_time_s, clock.now_s()))
            self.tick(inp, clock.now_s(), release, boundary_faults=bad_time)
            last = inp
            answered += 1
        if last is not None and ended in ("completed", "device finished"):
            self._await_final_status(last.tick + 1, stall_timeout_s)
        self._finish()
        return self.result(ended)

    def _await_final_status(self, status_tick: int, timeout_s: float) -> None:
        """Read the pump status that follows the last answered tick (the rate delivered over it).

        Waits until it arrives, the device finishes or closes the link, or ``timeout_s`` (s, wall).
        """
        ep = self.ep
        waited, poll_s = 0.0, min(0.05, timeout_s)
        try:
            while waited < timeout_s:
                status = ep.pump_status
                if status is not None and status.tick >= status_tick:
                    break
                if ep.peer_heartbeat is not None and ep.peer_heartbeat[1] == STATE_FINISHED:
                    break
                ep.poll(poll_s)
                waited += poll_s
        except LinkClosedError:
            pass
        status = ep.pump_status
        if status is not None and status.tick == status_tick:
            self.trajectory.delivered(status.tick, self.boundary.delivered(status.delivered_ml_h))

    def _silent_ticks(self, last: TickInputs, resume_tick: int, clock: VirtualClock) -> None:
        """Run ticks last.tick+1 … resume_tick−1 (nothing arrived) on the virtual clock.

        At most :meth:`_settle_ticks` of them one by one: by then the link loss has put the
        supervisor in FAILSAFE and its ramp has reached the safe rate, so every later silent tick
        would repeat the last one. The rest are skipped in one step (counted in the ticks per
        state, one event in the record), so a tick number that jumps by 10^6 or to 2^32 costs
        the same as a long link stall.
        """
        ts = self.period_s
        end = min(resume_tick, last.tick + 1 + self._settle_ticks())
        for j in range(last.tick + 1, end):
            now = j * ts
            age = (j - last.tick) * ts  # whole ticks: sim time on the wire is float32
            clock.advance_to(now)
            silent = replace(last, tick=j, sim_time_s=now)
            self.tick(
                silent,
                clock.now_s(),
                perf_counter_s(),
                sample_age_s=age,
                link_silence_s=age,
                send=False,
            )
        skipped = resume_tick - end
        if skipped > 0:
            self.ticks_in_state[self.sup.state] += skipped
            clock.advance_to((resume_tick - 1) * ts)
            self.events.note(
                end,
                end * ts,
                f"link silent: ticks {end}-{resume_tick - 1} ({skipped} ticks) skipped in one"
                f" step, {self.sup.state.name} at {self.sup.command_ml_h:g} ml/h",
            )

    def _settle_ticks(self) -> int:
        """Silent ticks (count) after which the supervisor's output no longer changes: the link
        loss, then the FAILSAFE ramp over the whole pump range, and one tick of margin."""
        cfg = self.sup.config
        settle_s = cfg.link_loss_after_s + cfg.max_rate_ml_h / cfg.failsafe_ramp_ml_h_per_s
        return math.ceil(settle_s / self.period_s) + 2

    def run_realtime(
        self,
        n_ticks: int,
        first_sample_timeout_s: float = 10.0,
        clock: MonotonicClock | None = None,
    ) -> LoopResult:
        """Run on the wall clock with absolute deadlines for ``n_ticks`` periods (0: until the end).

        Each period answers the newest sample received; stale samples and link silence feed the
        supervisor's watchdogs. Exits as :meth:`run_lockstep` does (the safe command first).
        """
        try:
            return self._realtime(n_ticks, first_sample_timeout_s, clock)
        except Exception as exc:
            return self._failed(exc)
        except BaseException as exc:
            self._fail_safe(exc)
            raise

    def _realtime(
        self, n_ticks: int, first_sample_timeout_s: float, clock: MonotonicClock | None
    ) -> LoopResult:
        ep = self.ep
        first = ep.wait_for_sample(first_sample_timeout_s)
        if first is None:
            raise DeviceStalled(f"no first sample within {first_sample_timeout_s} s")
        clock = clock or MonotonicClock()
        self._wall0 = perf_counter_s()
        sched = PeriodicSchedule(self.period_s, origin_s=clock.now_s())
        newest: TickInputs = first
        last_sample_s = last_frame_s = sched.origin_s
        frames_seen = ep.counters.frames_received
        skipped = 0
        ended = "completed"
        k = 0
        while n_ticks == 0 or k < n_ticks:
            if (stop := stop_requested()) is not None:
                ended = self._stop_safe(newest, stop)
                break
            deadline = sched.deadline_s()
            now = clock.wait_until(deadline)
            release = perf_counter_s()
            try:
                ep.poll(0.0)
            except LinkClosedError:
                ended = "device closed the link"
                break
            fresh = ep.newest_sample()  # older unanswered samples are superseded, not queued
            if fresh is not None:
                newest = fresh
                last_sample_s = now
            if ep.counters.frames_received != frames_seen:
                frames_seen = ep.counters.frames_received
                last_frame_s = now
            checked, bad_time = self.boundary.sample_time(newest)
            self.tick(
                checked,
                now,
                release,
                sample_age_s=now - last_sample_s,
                link_silence_s=now - last_frame_s,
                lateness_s=now - deadline,
                skipped=skipped,
                boundary_faults=bad_time,
            )
            k += 1
            if ep.peer_heartbeat is not None and ep.peer_heartbeat[1] == STATE_FINISHED:
                ended = "device finished"
                break
            _, skipped = sched.next_release(clock.now_s())
        self._finish()
        return self.result(ended)

    # ------------------------------------------------------------------ ending
    def safe_rate_ml_h(self) -> float:
        """The documented safe command (ml/h): the supervisor's safe rate, else the last
        command, held."""
        safe = self.sup.config.safe_rate_ml_h
        return self._last_command if safe is None else safe

    def _stop_safe(self, last: TickInputs | None, signum: int) -> str:
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

    def _finish(self) -> None:
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
