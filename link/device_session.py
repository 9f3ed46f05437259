"""The device's end of the link: send each tick's inputs and the pump status, wait for commands.

Per tick k the device sends :meth:`DeviceSession.send_tick` (scheduling parameters, target, then
the MAP sample; the runtime assembles a tick from its frames in any order), waits for the command
answering k (:meth:`DeviceSession.wait_for_command`), and after advancing sends
:meth:`DeviceSession.send_pump_status`.
"""

from __future__ import annotations

import time
from typing import Any

from pressor.link.dialect import pressor as mavlink
from pressor.link.messages import ROLE_DEVICE, ROLE_RUNTIME, Command, Hello, PumpStatus, TickInputs
from pressor.link.session import Session

_ID_SCHED = mavlink.MAVLINK_MSG_ID_SCHEDULING_PARAMS
_ID_TARGET = mavlink.MAVLINK_MSG_ID_MAP_TARGET
_ID_SAMPLE = mavlink.MAVLINK_MSG_ID_MAP_SAMPLE
_ID_COMMAND = mavlink.MAVLINK_MSG_ID_INFUSION_COMMAND
_ID_STATUS = mavlink.MAVLINK_MSG_ID_PUMP_STATUS


class DeviceSession(Session):
    """The pump/patient device's end of the link.

    Parameters
    ----------
    port, signing, clock, tlog, system_id, component_id
        As for :class:`~pressor.link.session.Session`; ``clock`` is the device's sim time (s), set by its
        owner (a :class:`~pressor.link.session.ManualClock`).
    """

    ROLE = ROLE_DEVICE
    PEER_ROLE = ROLE_RUNTIME
    PEER_NAME = "runtime"
    MAV_TYPE = mavlink.MAV_TYPE_GENERIC

    def __init__(self, port: Any, **kw: Any) -> None:
        super().__init__(port, **kw)
        self._commands: list[Command] = []
        self._handlers[_ID_COMMAND] = self._on_command

    # ------------------------------------------------------------------ sending
    def send_tick(self, inputs: TickInputs, *, flush: bool = True, sample: bool = True) -> None:
        """Send tick k's scheduling parameters, target and MAP sample (in that order); with
        ``sample=False`` (real time, the monitor has no new value) the first two only."""
        send = self.send_fields
        k = inputs.tick
        send(_ID_SCHED, k, inputs.K, inputs.T_s, inputs.tau_s, int(inputs.sched_valid), flush=False)
        send(_ID_TARGET, k, inputs.target_mmhg, flush=not sample and flush)
        if sample:
            send(_ID_SAMPLE, inputs.sim_time_s, k, inputs.map_mmhg, inputs.quality, flush=flush)

    def send_pump_status(self, status: PumpStatus, *, flush: bool = True) -> None:
        """Send the pump status (ml/h, ml, alarm flags) after an advance."""
        self.send_fields(
            _ID_STATUS,
            status.tick,
            status.delivered_ml_h,
            status.volume_ml,
            status.alarms,
            flush=flush,
        )

    def reset_session(self) -> None:
        """Forget received bytes and pending commands and number frames from 0 again (a simulated
        reconnection; the runtime sees a sequence gap)."""
        super().reset_session()
        self._commands.clear()

    # ---------------------------------------------------------------- receiving
    def _on_command(self, fields: tuple) -> None:
        self._commands.append(Command(*fields))

    def wait_for_command(self, tick: int, timeout_s: float) -> Command | None:
        """The infusion command answering ``tick``; ``None`` after ``timeout_s`` (s, wall clock).

        Commands for earlier ticks (late duplicates of answers already applied) are dropped and
        counted in ``duplicates``; commands for later ticks (a confused peer) in ``stale``.
        """
        pending = self._commands

        def ready() -> Command | None:
            while pending:
                cmd = pending.pop(0)
                if cmd.tick == tick:
                    return cmd
                if cmd.tick < tick:
                    self.counters.duplicates += 1
                else:
                    self.counters.stale += 1
            return None

        return self._wait(ready, timeout_s)

    # ---------------------------------------------------------------- handshake
    def _exchange_hellos(self, hello: Hello, timeout_s: float, resend_s: float) -> Hello | None:
        """Announce this device every ``resend_s`` (s) until the runtime answers (the runtime's
        port may have flushed earlier hellos when it opened)."""
        deadline = time.monotonic() + timeout_s
        peer: Hello | None = None
        while peer is None:
            left = deadline - time.monotonic()
            if left <= 0:
                break
            self.send_hello(hello)
            peer = self.wait_for_hello(min(resend_s, left))
        return peer
