"""The fixed-rate loop: the shell around the controller step (PX4 module style).

Each tick: read the newest MAP sample, target and scheduling parameters from the link, pass them
through the :class:`~runtime.supervisor.Supervisor`, step the controller (a pure call), send the
command, record. The loop counts its own timing (:class:`~runtime.timing.TimingStats`).

Two ways to keep time (injected clocks, :mod:`runtime.clock`):

Lockstep (default in ``pressor sil``)
    The device sends tick k's sample and waits for tick k's command (PX4 SITL style); the runtime's
    :class:`~runtime.clock.VirtualClock` follows the sample's sim time. The order per tick is the
    in-process simulator's (observe → step → apply → advance), so with a clean link the serial run
    reproduces it sample for sample. A device that sends nothing for ``stall_timeout_s`` of *wall*
    time ends the run with :class:`DeviceStalled`: in lockstep sim time stands still while the
    device is silent, and declaring link loss from wall time would make the trajectory depend on
    host load.

    Link stalls in virtual time. The device is the clock: a stalled or disconnected link is
    simulated by a device that keeps simulating without exchanging frames (``link-stall``,
    ``link-disconnect``), so the next sample that arrives is tick k > last + 1. The loop then runs
    the silent ticks last+1 … k−1 through the supervisor on the virtual clock (sample age and
    link silence growing by one period per tick, the newest sample being the last one received),
    recording each of them - with MAP NaN, nothing was measured - but sending nothing: nobody
    would receive it. So STALE_SAMPLE (HOLD) and LINK_LOSS (FAILSAFE) are logged at exactly the
    ticks a wall-clock runtime would have logged them, and tick k resumes from the safe state.

Real time (``--realtime``)
    The :class:`~runtime.clock.MonotonicClock` releases a tick at each absolute deadline
    ``t0 + k·Ts``; the loop drains the link, takes the newest sample and answers it. Sample age and
    link silence are measured on the wall clock, so the stale-sample and link-loss watchdogs are
    real. Lateness and skipped periods are counted.

Execution time of a tick = wall time from release (lockstep: sample decoded; real time: deadline
reached) to the command written to the port. Recording happens after the command is sent. The same
tick takes longer in real time than in lockstep (development VM, LPV: p50 ~180 µs against ~36 µs)
because after 100 ms asleep the interpreter's code and data are no longer in the CPU caches: a
fixed 20 µs piece of Python measured 40-54 µs when run once every 100 ms.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from contracts.controller import Controller
from link import (
    MODE_AUTO,
    MODE_SAFE,
    STATE_FINISHED,
    STATE_RUNNING,
    LinkClosedError,
    RuntimeSession,
    TickInputs,
)
from runtime.clock import MonotonicClock, PeriodicSchedule, VirtualClock, perf_counter_s
from runtime.recorder import CHANNEL_INDEX, CHANNELS, Recorder
from runtime.supervisor import State, Supervisor, SupervisorConfig, fault_names
from runtime.timing import TimingStats

_NAN = math.nan


class DeviceStalled(RuntimeError):
    """The device sent no sample for ``stall_timeout_s`` (wall clock) in lockstep."""


@dataclass
class Trajectory:
    """Per-tick signals of a run, in preallocated arrays that grow by doubling.

    Attributes (after :meth:`arrays`): ``tick``, ``sim_time_s``, ``map_mmhg`` (as measured),
    ``target_mmhg``, ``command_ml_h`` (sent to the pump), ``controller_ml_h`` (the controller's raw
    output, NaN when it did not run), ``faults`` (supervisor fault bits), ``state``.
    """

    capacity: int = 1 << 14
    n: int = 0
    ring: bool = False
    data: np.ndarray = field(init=False)

    FIELDS = (
        "tick",
        "sim_time_s",
        "map_mmhg",
        "target_mmhg",
        "command_ml_h",
        "controller_ml_h",
        "faults",
    )

    def __post_init__(self) -> None:
        shape = (self.capacity, len(self.FIELDS) + 1)
        # a ring is written to once up front, so its pages count in RSS from the start
        self.data = np.full(shape, np.nan) if self.ring else np.empty(shape, dtype=np.float64)

    def append(self, row: tuple[float, ...]) -> None:
        """Store one tick (FIELDS order, then the state); a ring keeps the last ``capacity``."""
        cap = self.data.shape[0]
        if self.n >= cap:
            if self.ring:
                self.data[self.n % cap] = row
                self.n += 1
                return
            self.data = np.concatenate([self.data, np.empty_like(self.data)])
        self.data[self.n] = row
        self.n += 1

    def arrays(self) -> dict[str, np.ndarray]:
        """Copies of the recorded columns by name (a ring: the last ``capacity`` ticks)."""
        if self.ring and self.n > self.capacity:
            i = self.n % self.capacity
            d = np.concatenate([self.data[i:], self.data[:i]])
        else:
            d = self.data[: self.n]
        out = {name: d[:, i].copy() for i, name in enumerate(self.FIELDS)}
        out["tick"] = out["tick"].astype(np.int64)
        out["faults"] = out["faults"].astype(np.int64)
        out["state"] = d[:, -1].astype(np.int64)
        return out


@dataclass
class LoopResult:
    """What a run produced: the trajectory, timing, link counters and supervisor account."""

    trajectory: dict[str, np.ndarray]
    timing: dict[str, float | int]
    link: dict[str, int]
    detections: dict[str, int]
    ticks_in_state: dict[str, int]
    transitions: list[dict[str, Any]]
    commands_out_of_range: int
    ended: str
    wall_s: float = 0.0
    #: where the run executed (filled by the CLI: CPU wake-up latency request, CPU pinning)
    host: dict[str, Any] = field(default_factory=dict)


def sched_limits_of(controller: Controller) -> tuple[Any, Any]:
    """The design box and rate bounds a generated controller declares, else ``(None, None)``.

    Looked up on the instance, then on its module: ``GRID_LO``/``GRID_HI`` (3 values: K, T s,
    τ s) and ``RATE_BOUNDS`` (3 values per s) as ``codegen`` emits them. The PI baseline
    declares none (it is not scheduled), so its scheduling inputs are not checked.
    """
    module = sys.modules.get(type(controller).__module__)
    sources = (controller, module)

    def find(name: str) -> Any:
        for src in sources:
            if src is not None and hasattr(src, name):
                return getattr(src, name)
        return None

    lo, hi, rate = find("GRID_LO"), find("GRID_HI"), find("RATE_BOUNDS")
    box = None
    if lo is not None and hi is not None and len(lo) == 3 and len(hi) == 3:
        box = tuple((float(a), float(b)) for a, b in zip(lo, hi, strict=True))
    rates = tuple(float(r) for r in rate) if rate is not None and len(rate) == 3 else None
    return box, rates


def supervisor_config_for(
    controller: Controller, sensor_noise_mmhg: float, **overrides: Any
) -> SupervisorConfig:
    """A supervisor configuration matched to ``controller`` and the device's sensor.

    Sample period and pump limit come from the controller; the scheduling box and rates from
    :func:`sched_limits_of`; the flatline check is on only when the sensor is noisy (a noise-free
    simulated sensor legitimately repeats values). Leaving the design box or rate bounds is
    advisory by default (``sched_action="advise"``): the generated controller clamps and
    rate-limits ρ itself (DESIGN.md §2), and the simulated patients routinely leave the envelope
    (paper-tracking seed 3: K down to 0.18 < 0.25; τ moving ~1 s/s against a 0.1 s/s bound), so
    holding would stop LPV control of most patients. ``overrides`` replace any field.
    """
    box, rates = sched_limits_of(controller)
    cfg: dict[str, Any] = {
        "sample_period_s": float(controller.sample_period_s),
        "max_rate_ml_h": float(controller.max_rate_ml_h),
        "flatline_enabled": sensor_noise_mmhg > 0.0,
        "sched_required": box is not None,
        "sched_box": box,
        "sched_rate_bounds": rates,
        "sched_action": "advise",
        "stale_after_s": 3.5 * float(controller.sample_period_s),
    }
    cfg.update(overrides)
    return SupervisorConfig(**cfg)


class Loop:
    """The runtime loop over a connected :class:`~link.RuntimeSession`.

    Parameters
    ----------
    controller
        Any :class:`~contracts.controller.Controller` (stepped once per tick).
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
        :class:`contracts.faults.FaultScorer`'s ``update``).
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
    ) -> None:
        self.controller = controller
        self.sup = supervisor
        self.ep = endpoint
        self.recorder = recorder
        self.period_s = float(controller.sample_period_s)
        self.timing = TimingStats(self.period_s)
        self.trajectory = (
            Trajectory() if history_ticks is None else Trajectory(int(history_ticks), ring=True)
        )
        self.on_tick = on_tick
        self.heartbeat_every = max(1, int(heartbeat_every))
        self.ticks_in_state = [0] * len(State)
        self.transitions: list[dict[str, Any]] = []
        self.out_of_range = 0
        self._row = [_NAN] * len(CHANNELS)
        self._count = 0
        self._wall0 = perf_counter_s()
        self._link_errors_seen = 0

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
    ) -> float:
        """Supervise, step, send and record one tick; return the command (ml/h).

        ``send=False`` (a silent tick of a stalled link, see the module docstring) skips the
        link and records MAP as NaN (no sample arrived for this tick).
        """
        sup = self.sup
        errors = self._link_errors()
        pump = self.ep.pump_status
        fresh = send and pump is not None and pump.tick == inp.tick
        run = sup.assess(
            now_s,
            inp.map_mmhg,
            inp.quality,
            inp.K,
            inp.T_s,
            inp.tau_s,
            inp.sched_valid,
            sample_age_s,
            link_silence_s,
            inp.target_mmhg,
            errors,
            pump.delivered_ml_h if fresh else _NAN,
            pump.alarms if fresh else 0,
        )
        raw = (
            self.controller.step(inp.map_mmhg, inp.target_mmhg, inp.K, inp.T_s, inp.tau_s)
            if run
            else None
        )
        command = sup.finalize(raw)
        state = sup.state
        if send:
            if self._count % self.heartbeat_every == 0:
                self.ep.send_heartbeat(inp.tick, STATE_RUNNING, flush=False)
            self.ep.send_command(inp.tick, command, MODE_AUTO if state == State.AUTO else MODE_SAFE)
        exec_s = perf_counter_s() - release_wall_s
        self._count += 1
        self.timing.record(exec_s, lateness_s, skipped)
        if not 0.0 <= command <= sup.config.max_rate_ml_h:  # by construction never; counted anyway
            self.out_of_range += 1
        self.ticks_in_state[state] += 1
        raw_f = _NAN if raw is None else raw
        map_rec = inp.map_mmhg if send else _NAN
        self.trajectory.append(
            (inp.tick, inp.sim_time_s, map_rec, inp.target_mmhg, command, raw_f, sup.faults, state)
        )
        if sup.transition is not None:
            old, new, faults = sup.transition
            event = {
                "tick": inp.tick,
                "sim_time_s": inp.sim_time_s,
                "from": old.name,
                "to": new.name,
                "faults": fault_names(faults),
            }
            self.transitions.append(event)
            if self.recorder is not None:
                self.recorder.event(
                    inp.tick,
                    inp.sim_time_s,
                    f"{old.name} -> {new.name}: {', '.join(event['faults']) or 'inputs good'}",
                    warn=new in (State.HOLD, State.FAILSAFE),
                )
        elif sup.new_faults and self.recorder is not None:  # advisory faults: log, no transition
            self.recorder.event(
                inp.tick,
                inp.sim_time_s,
                f"{state.name}: advisory {', '.join(fault_names(sup.new_faults))}",
                warn=False,
            )
        if self.recorder is not None:
            self._record(inp, raw_f, command, state, exec_s, lateness_s, map_rec)
        if self.on_tick is not None:
            self.on_tick(inp.tick, int(state), int(sup.faults), command)
        return command

    def _link_errors(self) -> int:
        """Frames the link layer discarded since the previous tick."""
        c = self.ep.counters
        total = (
            c.bad_crc
            + c.junk_bytes
            + c.resyncs
            + c.seq_gaps
            + c.incomplete_ticks
            + c.refused_unsigned
            + c.refused_bad_signature
        )
        new = total - self._link_errors_seen
        self._link_errors_seen = total
        return new

    def _record(
        self,
        inp: TickInputs,
        raw: float,
        command: float,
        state: State,
        exec_s: float,
        lateness_s: float,
        map_mmhg: float,
    ) -> None:
        row = self._row
        ix = CHANNEL_INDEX
        pump = self.ep.pump_status
        c = self.ep.counters
        row[ix["/patient/map_mmhg"]] = map_mmhg
        row[ix["/controller/target_mmhg"]] = inp.target_mmhg
        row[ix["/controller/command_ml_h"]] = raw
        row[ix["/pump/command_ml_h"]] = command
        row[ix["/pump/rate_ml_h"]] = pump.delivered_ml_h if pump is not None else _NAN
        row[ix["/pump/volume_ml"]] = pump.volume_ml if pump is not None else _NAN
        row[ix["/schedule/K"]] = inp.K
        row[ix["/schedule/T_s"]] = inp.T_s
        row[ix["/schedule/tau_s"]] = inp.tau_s
        row[ix["/loop/exec_us"]] = exec_s * 1e6
        row[ix["/loop/lateness_us"]] = lateness_s * 1e6
        row[ix["/safety/state"]] = float(state)
        row[ix["/safety/faults"]] = float(self.sup.faults)
        row[ix["/safety/alarm"]] = 1.0 if self.sup.alarm else 0.0
        row[ix["/link/bad_frames"]] = float(
            c.bad_crc + c.refused_unsigned + c.refused_bad_signature + c.resyncs
        )
        assert self.recorder is not None
        self.recorder.record(inp.tick, inp.sim_time_s, row)

    # ------------------------------------------------------------------ drivers
    def run_lockstep(self, n_ticks: int, stall_timeout_s: float = 10.0) -> LoopResult:
        """Answer the device's samples one by one until ``n_ticks`` are answered (0: until it ends).

        Raises
        ------
        DeviceStalled
            No sample for ``stall_timeout_s`` (s, wall clock) while the device has not finished.
        """
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
            if inp is None:
                ended = "device finished"
                break
            if last is not None and inp.tick > last.tick + 1:
                self._silent_ticks(last, inp.tick, clock)
                answered += inp.tick - last.tick - 1
            release = perf_counter_s()
            clock.advance_to(inp.sim_time_s)
            self.tick(inp, clock.now_s(), release)
            last = inp
            answered += 1
        self._finish()
        return self.result(ended)

    def _silent_ticks(self, last: TickInputs, resume_tick: int, clock: VirtualClock) -> None:
        """Run ticks last.tick+1 … resume_tick−1 (nothing arrived) on the virtual clock."""
        ts = self.period_s
        for j in range(last.tick + 1, resume_tick):
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

    def run_realtime(
        self,
        n_ticks: int,
        first_sample_timeout_s: float = 10.0,
        clock: MonotonicClock | None = None,
    ) -> LoopResult:
        """Run on the wall clock with absolute deadlines for ``n_ticks`` periods (0: until the end).

        Each period answers the newest sample received; stale samples and link silence feed the
        supervisor's watchdogs.
        """
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
            self.tick(
                newest,
                now,
                release,
                sample_age_s=now - last_sample_s,
                link_silence_s=now - last_frame_s,
                lateness_s=now - deadline,
                skipped=skipped,
            )
            k += 1
            if ep.peer_heartbeat is not None and ep.peer_heartbeat[1] == STATE_FINISHED:
                ended = "device finished"
                break
            _, skipped = sched.next_release(clock.now_s())
        self._finish()
        return self.result(ended)

    def _finish(self) -> None:
        try:
            tr = self.trajectory
            last = int(tr.data[(tr.n - 1) % tr.data.shape[0], 0]) if tr.n else 0
            self.ep.send_heartbeat(last, STATE_FINISHED)
        except LinkClosedError:
            pass

    def result(self, ended: str) -> LoopResult:
        """Collect the run's account."""
        return LoopResult(
            trajectory=self.trajectory.arrays(),
            timing=self.timing.summary(),
            link=self.ep.counters.as_dict(),
            detections=dict(self.sup.detections),
            ticks_in_state={s.name: self.ticks_in_state[s] for s in State},
            transitions=list(self.transitions),
            commands_out_of_range=self.out_of_range,
            ended=ended,
            wall_s=perf_counter_s() - self._wall0,
        )
