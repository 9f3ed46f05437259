"""The runtime's end of the link: assemble each tick's inputs, send commands and heartbeats.

The device sends tick k as scheduling parameters, target, then MAP sample - the sample last, so
its arrival means the tick is complete (scheduling parameters are required only when the runtime
schedules on them, ``require_sched``: a device may send none). :meth:`RuntimeSession.wait_for_sample` returns the tick as
a :class:`~link.messages.TickInputs`; :meth:`RuntimeSession.send_command` answers it. When the
device retransmits a tick the runtime has already answered (the command was lost), the session
re-sends the same command by itself and counts it.
"""

from __future__ import annotations

import math
from typing import Any

from link.dialect import pressor as mavlink
from link.messages import (
    LINK_LOCKSTEP,
    MODE_AUTO,
    ROLE_DEVICE,
    ROLE_RUNTIME,
    Hello,
    PumpStatus,
    TickInputs,
)
from link.session import Session

_ID_SCHED = mavlink.MAVLINK_MSG_ID_SCHEDULING_PARAMS
_ID_TARGET = mavlink.MAVLINK_MSG_ID_MAP_TARGET
_ID_SAMPLE = mavlink.MAVLINK_MSG_ID_MAP_SAMPLE
_ID_COMMAND = mavlink.MAVLINK_MSG_ID_INFUSION_COMMAND
_ID_STATUS = mavlink.MAVLINK_MSG_ID_PUMP_STATUS


class RuntimeSession(Session):
    """The controller runtime's end of the link.

    Parameters
    ----------
    port, signing, tlog, system_id, component_id
        As for :class:`~link.session.Session`.
    clock
        The run clock. Default: a :class:`~link.session.ManualClock` at 0 that follows the sim
        time of the received MAP samples (lockstep virtual time); pass another (e.g. the monotonic
        clock in real-time mode) to use it instead.
    complete_ticks
        Lockstep peers only: deliver a MAP sample only together with its own tick's scheduling
        parameters and target; a sample whose companions were lost is dropped and left unanswered
        so the device retransmits the tick (the trajectory then stays identical to the in-process
        simulation). With a real-time peer samples are always delivered and
        ``TickInputs.sched_tick`` / ``target_tick`` tell the loop which values are stale.
    require_sched
        Whether a lockstep tick is complete only with its own SCHEDULING_PARAMS (default True:
        the runtime schedules on the device's values, ``--schedule oracle``). False when the
        runtime schedules on its own estimate or constants (``--schedule estimated|nominal``):
        a tick is then complete with its target and MAP sample, and a device that never sends
        scheduling parameters works (``TickInputs`` then carries NaN and ``sched_valid=False``).
    require_target
        Whether a lockstep tick is complete only with its own MAP_TARGET (default True). False
        when the runtime sets the target itself (``pressor run --target-mmhg``): ``TickInputs``
        then carries the device's latest target, if any, which the runtime's loop replaces.
    """

    ROLE = ROLE_RUNTIME
    PEER_ROLE = ROLE_DEVICE
    PEER_NAME = "device"
    MAV_TYPE = mavlink.MAV_TYPE_ONBOARD_CONTROLLER

    def __init__(
        self,
        port: Any,
        *,
        clock: Any = None,
        complete_ticks: bool = True,
        require_sched: bool = True,
        require_target: bool = True,
        **kw: Any,
    ) -> None:
        super().__init__(port, clock=clock, **kw)
        self.complete_ticks = complete_ticks
        self.require_sched = require_sched
        self.require_target = require_target
        self._follow_samples = clock is None
        #: the device's latest pump status (or None)
        self.pump_status: PumpStatus | None = None
        self._hello_reply_due = False
        # received tick data, as field tuples in XML order (see the handlers)
        self._samples: list[tuple[float, int, float, int]] = []
        self._sched: tuple[int, float, float, float, int] | None = None
        self._target: tuple[int, float] | None = None
        self._last_sample_tick = -1
        self._last_command: tuple[int, float, int] | None = None
        self._handlers.update(
            {
                _ID_SAMPLE: self._on_sample,
                _ID_SCHED: self._on_sched,
                _ID_TARGET: self._on_target,
                _ID_STATUS: self._on_pump_status,
            }
        )

    # ------------------------------------------------------------------ sending
    def send_command(self, tick: int, rate_ml_h: float, mode: int = MODE_AUTO) -> None:
        """Send the infusion command answering ``tick`` (ml/h, ``MODE_*``) and flush."""
        self._last_command = (tick, rate_ml_h, mode)
        self.send_fields(_ID_COMMAND, tick, rate_ml_h, mode)

    # ---------------------------------------------------------------- receiving
    def feed(self, data: bytes) -> None:
        """Process received bytes, then answer a device hello that asked for it."""
        super().feed(data)
        if self._hello_reply_due:
            self._hello_reply_due = False
            assert self._hello is not None
            self.send_hello(self._hello)

    def _on_hello(self, msg: Any) -> None:
        super()._on_hello(msg)
        # the runtime answers device hellos once it has announced itself (a device that missed the
        # first answer - its port flushed on open - keeps asking), at most once per read so that
        # hellos queued while the runtime was starting get one answer, and never once ticks flow
        if (
            self._hello is not None
            and msg.role == ROLE_DEVICE
            and self._last_sample_tick < 0
            and not self._samples
        ):
            self._hello_reply_due = True

    def _on_sample(self, fields: tuple) -> None:
        tick = fields[1]
        if self._samples and self._samples[-1][1] >= tick:
            self.counters.duplicates += 1  # retransmitted before the loop took the first copy
            return
        if tick <= self._last_sample_tick:
            # the device retransmitted a tick: answer again if we already did
            self.counters.duplicates += 1
            last = self._last_command
            if last is not None and last[0] == tick:
                self.counters.retransmits += 1
                self.send_fields(_ID_COMMAND, *last)
            return
        if self.complete_ticks:
            peer = self.peer_hello
            sched, target = self._sched, self._target
            if (
                peer is not None
                and peer.link_mode == LINK_LOCKSTEP
                and (
                    (self.require_sched and (sched is None or sched[0] != tick))
                    or (self.require_target and (target is None or target[0] != tick))
                )
            ):
                # in lockstep a stale value would change the trajectory: wait for the resend
                self.counters.incomplete_ticks += 1
                return
        self._samples.append(fields)

    def _on_sched(self, fields: tuple) -> None:
        self._sched = fields

    def _on_target(self, fields: tuple) -> None:
        self._target = fields

    def _on_pump_status(self, fields: tuple) -> None:
        self.pump_status = PumpStatus(*fields)

    def next_sample(self) -> TickInputs | None:
        """Non-blocking: the oldest sample already received and not yet returned.

        Call :meth:`poll` first to read the port.
        """
        if not self._samples:
            return None
        sim_time_s, tick, map_mmhg, quality = self._samples.pop(0)
        self._last_sample_tick = tick
        if self._follow_samples:
            self.clock.t = sim_time_s
        s, t = self._sched, self._target
        nan = math.nan
        if s is None:
            s = (-1, nan, nan, nan, 0)
        return TickInputs(
            tick,
            sim_time_s,
            map_mmhg,
            quality,
            t[1] if t is not None else nan,
            s[1],
            s[2],
            s[3],
            bool(s[4]),
            s[0],
            t[0] if t is not None else -1,
        )

    def newest_sample(self) -> TickInputs | None:
        """Non-blocking: the newest sample already received; older ones not yet returned are
        superseded (counted in ``stale``). ``None`` when nothing new arrived.
        """
        samples = self._samples
        if not samples:
            return None
        if len(samples) > 1:
            self.counters.stale += len(samples) - 1
            del samples[:-1]
        return self.next_sample()

    def wait_for_sample(self, timeout_s: float) -> TickInputs | None:
        """The next new MAP sample with the tick's scheduling parameters and target.

        Waits at most ``timeout_s`` (wall clock). Returns ``None`` on timeout (counted in
        ``timeouts``). Samples are returned in arrival order, each once; retransmitted ones are
        answered automatically (see the module docstring).

        Raises
        ------
        LinkClosedError
            The peer closed the link.
        """
        return self._wait(self.next_sample, timeout_s)

    # ---------------------------------------------------------------- handshake
    def _exchange_hellos(self, hello: Hello, timeout_s: float, resend_s: float) -> Hello | None:
        """Wait for the device's hello and answer it (and any later one, see :meth:`_on_hello`);
        one buffered before the handshake began is answered here."""
        self._hello = hello
        if self.peer_hello is not None:
            self.send_hello(hello)
        return self.wait_for_hello(timeout_s)
