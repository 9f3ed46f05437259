"""The runtime's end of the link: assemble each tick's inputs, send commands and heartbeats.

A lockstep tick is assembled whatever order its frames arrive in: the MAP sample waits until the
rest of its tick is there - SCHEDULING_PARAMS if ``require_sched``, MAP_TARGET if
``require_target``, and PUMP_STATUS once the device has sent one numbered as docs/PROTOCOL.md
says - and the tick goes to the loop as soon as it is complete (docs/PROTOCOL.md, "Required and
optional").
:meth:`RuntimeSession.wait_for_sample` returns it as a :class:`~pressor.link.messages.TickInputs`;
:meth:`RuntimeSession.send_command` answers it. A tick whose frames were lost stays unanswered
until the device resends it (its pump status is not resent: the tick then goes without it).
When the device retransmits a tick the runtime has already answered (the command was lost), the
session re-sends the same command by itself. Whatever is dropped is counted by cause
(:class:`~pressor.link.counters.LinkCounters`, ``DROP_CAUSES``).
"""

from __future__ import annotations

import math
from typing import Any

from pressor.link.counters import HelloRefused
from pressor.link.dialect import pressor as mavlink
from pressor.link.handshake import hello_change, hello_of
from pressor.link.messages import (
    LINK_LOCKSTEP,
    MODE_AUTO,
    ROLE_DEVICE,
    ROLE_RUNTIME,
    Hello,
    PumpStatus,
    TickInputs,
)
from pressor.link.session import Session

_ID_SCHED = mavlink.MAVLINK_MSG_ID_SCHEDULING_PARAMS
_ID_TARGET = mavlink.MAVLINK_MSG_ID_MAP_TARGET
_ID_SAMPLE = mavlink.MAVLINK_MSG_ID_MAP_SAMPLE
_ID_COMMAND = mavlink.MAVLINK_MSG_ID_INFUSION_COMMAND
_ID_STATUS = mavlink.MAVLINK_MSG_ID_PUMP_STATUS
#: the latest sample time (s) the run clock follows: 2^32 ticks of the longest period (10 s)
_MAX_RUN_S = 4.3e10


class RuntimeSession(Session):
    """The controller runtime's end of the link.

    Parameters
    ----------
    port, signing, tlog, system_id, component_id
        As for :class:`~pressor.link.session.Session`.
    clock
        The run clock. Default: a :class:`~pressor.link.session.ManualClock` at 0 that follows the sim
        time of the received MAP samples (lockstep virtual time); pass another (e.g. the monotonic
        clock in real-time mode) to use it instead.
    complete_ticks
        Lockstep peers only: deliver a MAP sample only once its tick is complete (see the module
        docstring), so the trajectory stays identical to the in-process simulation. The tick then
        carries the scheduling parameters and target of its own tick; one that is not required
        and had not arrived when the tick was complete is NaN with ``sched_tick`` /
        ``target_tick`` -1 (``sched_valid`` False). With a real-time peer (or ``False``) samples
        are delivered at once with the latest scheduling parameters and target received, and
        ``sched_tick`` / ``target_tick`` tell the loop which values are stale.
    require_sched
        Whether a lockstep tick needs its own SCHEDULING_PARAMS (default True: the runtime
        schedules on the device's values, ``--schedule oracle``). False when the runtime
        schedules on its own estimate or constants (``--schedule estimated|nominal``): a device
        that never sends scheduling parameters then works.
    require_target
        Whether a lockstep tick needs its own MAP_TARGET (default True: the device plays the
        clinician's console). False when the runtime has its own target: the tick's
        ``target_mmhg`` is then the device's value for that tick if it came before the tick was
        complete, else NaN (``target_tick`` -1).
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
        #: the device's hello the run started on (:meth:`lock_terms`), else None
        self._terms: Hello | None = None
        #: refusals of hellos that tried to change the run, not yet taken by the loop
        self.hello_changes: list[HelloRefused] = []
        # received tick data, as field tuples in XML order (see the handlers): samples ready for
        # the loop, each with the scheduling and target frames of its own tick taken when the
        # lockstep tick was complete (None: real time, the latest ones at hand-over)
        self._samples: list[tuple[tuple, tuple | None]] = []
        self._sched: tuple[int, float, float, float, int] | None = None
        self._target: tuple[int, float] | None = None
        #: lockstep: the sample waiting for the rest of its tick; the tick and what it lacked
        #: when a read ended with it pending (counted if the device resends it)
        self._pending: tuple[float, int, float, int] | None = None
        self._waited: tuple[int, tuple[str, ...]] | None = None
        #: the device sends PUMP_STATUS numbered k+1 after the command for k: lockstep ticks wait
        #: for theirs (a device numbering it otherwise is not waited for)
        self._status_seen = False
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
        pending = self._pending
        if pending is not None:  # a read ended with the tick incomplete: remember what it lacks
            self._waited = (pending[1], self._missing(pending[1]))
        if self._hello_reply_due:
            self._hello_reply_due = False
            assert self._hello is not None
            self.send_hello(self._hello)

    def lock_terms(self) -> None:
        """The device's hello was checked and the run starts on it: from now on a hello may not
        change it (:meth:`_on_hello`, :func:`pressor.link.handshake.hello_change`)."""
        self._terms = self.peer_hello

    def take_hello_changes(self) -> list[HelloRefused]:
        """The refusals of the hellos that tried to change the run since the last call (each
        already sent to the device)."""
        changes, self.hello_changes = self.hello_changes, []
        return changes

    def _on_hello(self, msg: Any) -> None:
        first = self._terms
        if first is not None:  # the run's terms are set: a later hello may not change them
            if msg.get_srcSystem() != self.PEER_ROLE:
                self.counters.wrong_system += 1  # an echo of this end's hello, a third node
                return
            refusal = hello_change(first, hello_of(msg), self.PEER_NAME)
            if refusal is not None:  # told at once; the run keeps the first hello's terms
                self.hello_changes.append(refusal)
                self.refuse(refusal, fault=False)
            return
        super()._on_hello(msg)
        # the runtime answers device hellos once it has announced itself (a device that missed the
        # first answer - its port flushed on open - keeps asking), at most once per read so that
        # hellos queued while the runtime was starting get one answer, and never once ticks flow
        if (
            self._hello is not None
            and msg.role == ROLE_DEVICE
            and self._last_sample_tick < 0
            and not self._samples
            and self._pending is None
        ):
            self._hello_reply_due = True

    def _on_sample(self, fields: tuple) -> None:
        tick = fields[1]
        c = self.counters
        pending = self._pending
        newest = max(
            self._last_sample_tick,
            self._samples[-1][0][1] if self._samples else -1,
            -1 if pending is None else pending[1],
        )
        if tick < newest:
            c.old_ticks += 1  # an earlier tick than one already held or answered
            return
        if tick == newest:
            c.duplicates += 1  # the device resent the tick, or the link duplicated the frame
            self._on_resend(tick)
            last = self._last_command
            if tick == self._last_sample_tick and last is not None and last[0] == tick:
                c.retransmits += 1  # the answer was lost: answer again
                self.send_fields(_ID_COMMAND, *last)
            return
        if pending is not None:  # the device moved on without completing the pending tick
            self._count_incomplete(self._missing(pending[1]))
            self._pending = None
        peer = self.peer_hello
        if self.complete_ticks and peer is not None and peer.link_mode == LINK_LOCKSTEP:
            self._pending = fields
            self._try_complete(resent=False)
        else:
            self._samples.append((fields, None))

    def _on_sched(self, fields: tuple) -> None:
        self._sched = fields
        if self._pending is not None:
            self._try_complete(resent=False)

    def _on_target(self, fields: tuple) -> None:
        self._target = fields
        if self._pending is not None:
            self._try_complete(resent=False)

    def _on_pump_status(self, fields: tuple) -> None:
        status = self.pump_status = PumpStatus(*fields)
        pending = self._pending
        peer = self.peer_hello
        if (
            status.tick <= self._last_sample_tick
            and peer is not None
            and peer.link_mode == LINK_LOCKSTEP
        ):
            # after the command for k only a status numbered k+1 can follow: this one is
            # numbered for a tick already answered and its pump checks cannot run
            self.counters.misnumbered_status += 1
        if status.tick == (self._last_sample_tick + 1 if pending is None else pending[1]):
            self._status_seen = True  # numbered as the protocol says: lockstep waits for it
        if pending is not None:
            self._try_complete(resent=False)

    # ----------------------------------------------------------- tick assembly
    def _missing(self, tick: int) -> tuple[str, ...]:
        """What lockstep tick ``tick`` still lacks: ``sched`` (only if ``require_sched``),
        ``target`` (only if ``require_target``), ``status`` (once the device sent one numbered as
        the protocol says)."""
        sched, target, status = self._sched, self._target, self.pump_status
        missing = []
        if self.require_sched and (sched is None or sched[0] != tick):
            missing.append("sched")
        if self.require_target and (target is None or target[0] != tick):
            missing.append("target")
        if self._status_seen and (status is None or status.tick != tick):
            missing.append("status")
        return tuple(missing)

    def _try_complete(self, *, resent: bool) -> None:
        """Hand the pending sample to the loop if its tick is complete (or, on the device's
        resend, lacks only its pump status, which the device does not resend)."""
        pending = self._pending
        assert pending is not None
        tick = pending[1]
        missing = self._missing(tick)
        if missing and not (resent and missing == ("status",)):
            return
        self._pending = None
        sched, target = self._sched, self._target
        own = (
            sched if sched is not None and sched[0] == tick else None,
            target if target is not None and target[0] == tick else None,
        )
        self._samples.append((pending, own))

    def _on_resend(self, tick: int) -> None:
        """A sample of ``tick`` came again: if a read ended with that tick incomplete, the
        device resent it because its first copy lacked something: count what, and deliver a
        tick that now lacks only its pump status."""
        waited = self._waited
        if waited is None or waited[0] != tick:
            return
        self._waited = None
        self._count_incomplete(waited[1])
        if self._pending is not None and self._pending[1] == tick:
            self._try_complete(resent=True)

    def _count_incomplete(self, missing: tuple[str, ...]) -> None:
        c = self.counters
        if "sched" in missing:
            c.incomplete_sched += 1
        if "target" in missing:
            c.incomplete_target += 1
        if "status" in missing:
            c.incomplete_status += 1

    def next_sample(self) -> TickInputs | None:
        """Non-blocking: the oldest sample already received and not yet returned.

        Call :meth:`poll` first to read the port.
        """
        if not self._samples:
            return None
        fields, own = self._samples.pop(0)
        sim_time_s, tick, map_mmhg, quality = fields
        self._last_sample_tick = tick
        if self._follow_samples and self.clock.t <= sim_time_s <= _MAX_RUN_S:  # False for NaN
            # the run clock (tlog stamps, seed-key signing) never runs backwards or off the
            # scale; the loop judges the sample's time itself (SAMPLE_TIME)
            self.clock.t = sim_time_s
        s, t = own if own is not None else (self._sched, self._target)
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
        """The next tick: a new MAP sample with its tick's scheduling parameters and target
        (lockstep: once the tick is complete, see the module docstring).

        Waits at most ``timeout_s`` (wall clock). Returns ``None`` on timeout (counted in
        ``timeouts``). Ticks are returned in order, each once; retransmitted ones are answered
        automatically.

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
