"""The two ways the runtime loop keeps time: its drivers, each a loop over ticks that calls
:meth:`pressor.runtime.shell.loop.Loop.tick` (the loop itself holds the per-tick work and the run's
account; :mod:`pressor.runtime.shell.loop`).

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

A stop signal (:mod:`pressor.runtime.shell.interrupt`) ends either driver at a tick boundary after
a safe-rate command (:meth:`~pressor.runtime.shell.loop.Loop.stop_safe`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

from pressor.link import STATE_FINISHED, LinkClosedError, TickInputs
from pressor.runtime.shell.clock import (
    MonotonicClock,
    PeriodicSchedule,
    VirtualClock,
    perf_counter_s,
)
from pressor.runtime.shell.interrupt import stop_requested
from pressor.runtime.shell.trajectory import LoopResult

if TYPE_CHECKING:
    from pressor.runtime.shell.loop import Loop


class DeviceStalled(RuntimeError):
    """The device sent no sample for ``stall_timeout_s`` (wall clock) in lockstep."""


def lockstep(loop: Loop, n_ticks: int, stall_timeout_s: float) -> LoopResult:
    """Answer the device's samples one by one until ``n_ticks`` are answered (0: until it ends)
    (:meth:`pressor.runtime.shell.loop.Loop.run_lockstep`, which sends the safe command when this
    raises)."""
    clock = VirtualClock()
    ep = loop.ep
    loop.start_wall_clock()
    loop.link_errors()  # what the handshake saw is not a fault of tick 0
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
                            f"device sent no sample for {stall_timeout_s} s after {answered} ticks"
                        )
        except LinkClosedError:
            ended = "device closed the link"
            break
        if inp is None:  # the device finished, or a stop signal came
            ended = "device finished" if stop is None else loop.stop_safe(last, stop)
            break
        if last is not None and inp.tick > last.tick + 1:
            _silent_ticks(loop, last, inp.tick, clock)
            answered += inp.tick - last.tick - 1
        release = perf_counter_s()
        inp, bad_time = loop.boundary.sample_time(inp)
        clock.advance_to(max(inp.sim_time_s, clock.now_s()))
        loop.tick(inp, clock.now_s(), release, boundary_faults=bad_time)
        last = inp
        answered += 1
    if last is not None and ended in ("completed", "device finished"):
        _await_final_status(loop, last.tick + 1, stall_timeout_s)
    loop.finish()
    return loop.result(ended)


def _await_final_status(loop: Loop, status_tick: int, timeout_s: float) -> None:
    """Read the pump status that follows the last answered tick (the rate delivered over it).

    Waits until it arrives, the device finishes or closes the link, or ``timeout_s`` (s, wall).
    """
    ep = loop.ep
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
        loop.trajectory.delivered(status.tick, loop.boundary.delivered(status.delivered_ml_h))


def _silent_ticks(loop: Loop, last: TickInputs, resume_tick: int, clock: VirtualClock) -> None:
    """Run ticks last.tick+1 … resume_tick−1 (nothing arrived) on the virtual clock.

    At most :func:`_settle_ticks` of them one by one: by then the link loss has put the
    supervisor in FAILSAFE and its ramp has reached the safe rate, so every later silent tick
    would repeat the last one. The rest are skipped in one step (counted in the ticks per
    state, one event in the record), so a tick number that jumps by 10^6 or to 2^32 costs
    the same as a long link stall.
    """
    ts = loop.period_s
    end = min(resume_tick, last.tick + 1 + _settle_ticks(loop))
    for j in range(last.tick + 1, end):
        now = j * ts
        age = (j - last.tick) * ts  # whole ticks: sim time on the wire is float32
        clock.advance_to(now)
        silent = replace(last, tick=j, sim_time_s=now)
        loop.tick(
            silent,
            clock.now_s(),
            perf_counter_s(),
            sample_age_s=age,
            link_silence_s=age,
            send=False,
        )
    skipped = resume_tick - end
    if skipped > 0:
        loop.ticks_in_state[loop.sup.state] += skipped
        clock.advance_to((resume_tick - 1) * ts)
        loop.events.note(
            end,
            end * ts,
            f"link silent: ticks {end}-{resume_tick - 1} ({skipped} ticks) skipped in one"
            f" step, {loop.sup.state.name} at {loop.sup.command_ml_h:g} ml/h",
        )


def _settle_ticks(loop: Loop) -> int:
    """Silent ticks (count) after which the supervisor's output no longer changes: the link
    loss, then the FAILSAFE ramp over the whole pump range, and one tick of margin."""
    cfg = loop.sup.config
    settle_s = cfg.link_loss_after_s + cfg.max_rate_ml_h / cfg.failsafe_ramp_ml_h_per_s
    return math.ceil(settle_s / loop.period_s) + 2


def realtime(
    loop: Loop, n_ticks: int, first_sample_timeout_s: float, clock: MonotonicClock | None
) -> LoopResult:
    """Run on the wall clock with absolute deadlines for ``n_ticks`` periods (0: until the end)
    (:meth:`pressor.runtime.shell.loop.Loop.run_realtime`, which sends the safe command when this
    raises)."""
    ep = loop.ep
    first = ep.wait_for_sample(first_sample_timeout_s)
    if first is None:
        raise DeviceStalled(f"no first sample within {first_sample_timeout_s} s")
    clock = clock or MonotonicClock()
    loop.start_wall_clock()
    sched = PeriodicSchedule(loop.period_s, origin_s=clock.now_s())
    newest: TickInputs = first
    last_sample_s = last_frame_s = sched.origin_s
    frames_seen = ep.counters.frames_received
    skipped = 0
    ended = "completed"
    k = 0
    while n_ticks == 0 or k < n_ticks:
        if (stop := stop_requested()) is not None:
            ended = loop.stop_safe(newest, stop)
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
        checked, bad_time = loop.boundary.sample_time(newest)
        loop.tick(
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
    loop.finish()
    return loop.result(ended)
