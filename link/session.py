"""One end of the pressor link: typed sends and receives over a byte port.

A :class:`Session` owns a port (see :mod:`pressor.link.ports`), a :class:`~pressor.link.codec.FrameCodec` (framing,
signing, sequence checks), a send queue and :class:`~pressor.link.counters.LinkCounters`. It never sleeps
except inside a bounded wait on the port. What the two roles send and wait for lives in the
subclasses, :class:`pressor.link.runtime_session.RuntimeSession` and
:class:`pressor.link.device_session.DeviceSession`; this base holds what both ends share: hellos and the
handshake and its refusals, heartbeats, reading, dispatching, the tlog and closing.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import suppress
from dataclasses import replace
from typing import Any

import serial

from pressor.link.codec import FrameCodec, message_object
from pressor.link.counters import (
    HelloRefused,
    LinkClosedError,
    LinkCounters,
    LinkError,
    PeerRefused,
    SigningMismatch,
)
from pressor.link.dialect import pressor as mavlink
from pressor.link.handshake import check_peer_hello, field_text, hello_of, signing_mismatch
from pressor.link.messages import (
    PROTOCOL_VERSION,
    REFUSAL_SIGNING,
    REFUSAL_TEXT_CHARS,
    STATE_FAULT,
    Heartbeat,
    Hello,
)
from pressor.link.signing import Signing
from pressor.link.tlog import TlogWriter

#: ``hello_of`` is re-exported: it was defined here
__all__ = ["ManualClock", "Session", "hello_of"]

_ID_HEARTBEAT = mavlink.MAVLINK_MSG_ID_PRESSOR_HEARTBEAT
_ID_HELLO = mavlink.MAVLINK_MSG_ID_PRESSOR_HELLO
_ID_STD_HEARTBEAT = mavlink.MAVLINK_MSG_ID_HEARTBEAT
_ID_REFUSAL = mavlink.MAVLINK_MSG_ID_PRESSOR_REFUSAL
#: standard HEARTBEAT system_status for each PRESSOR_STATE
_MAV_STATE = {
    mavlink.PRESSOR_STATE_BOOT: mavlink.MAV_STATE_BOOT,
    mavlink.PRESSOR_STATE_RUNNING: mavlink.MAV_STATE_ACTIVE,
    mavlink.PRESSOR_STATE_FINISHED: mavlink.MAV_STATE_STANDBY,
    mavlink.PRESSOR_STATE_FAULT: mavlink.MAV_STATE_CRITICAL,
}


class ManualClock:
    """Run clock set by its owner (virtual time, s). Calling it returns the current time."""

    __slots__ = ("t",)

    def __init__(self, t: float = 0.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


class Session:
    """What both ends of the link do; use :class:`~pressor.link.runtime_session.RuntimeSession` or
    :class:`~pressor.link.device_session.DeviceSession`.

    Parameters
    ----------
    port
        A pyserial port or anything with ``write``, ``read``, ``in_waiting`` (see
        :mod:`pressor.link.ports`). Its ``timeout`` should be short (~10 ms): waits loop on it.
    signing
        Sign outgoing frames and check incoming ones; ``None`` = no signing (and signed incoming
        frames are then accepted unchecked, as pymavlink does - give the pump side a key).
    clock
        The run clock (callable returning s). Default: a :class:`ManualClock` at 0.
    tlog
        Log every sent and accepted frame with the run clock's timestamp.
    system_id, component_id
        MAVLink ids of this end (default: the role value, component 1).
    """

    #: this end's role (``ROLE_*``) and the peer's, with the peer's name for messages; the
    #: MAV_TYPE its standard HEARTBEAT announces
    ROLE: int
    MAV_TYPE: int
    PEER_ROLE: int
    PEER_NAME: str

    def __init__(
        self,
        port: Any,
        *,
        signing: Signing | None = None,
        clock: Any = None,
        tlog: TlogWriter | None = None,
        system_id: int | None = None,
        component_id: int = 1,
    ) -> None:
        self.port = port
        self.counters = LinkCounters()
        self.clock = clock if clock is not None else ManualClock()
        self.tlog = tlog
        self.signing = signing
        #: framing, signing and sequence numbers of this end
        self.codec = FrameCodec(
            system_id or self.ROLE, component_id, signing, self.clock, self.counters
        )
        # only the peer's frames count (its system id is its role): this end's own frames
        # echoed back by the line are dropped (``wrong_system``), never taken for its liveness
        self.codec.peer_system = self.PEER_ROLE
        #: the port's one-syscall read (``ttyport.FdPort`` / ``FastPort``), if it has one
        self._read_some: Callable[[float], bytes] | None = getattr(port, "read_some", None)
        self._tx = bytearray()
        self.closed = False
        #: called with every accepted message object (after the session's own handling)
        self.on_message: Callable[[Any], None] | None = None
        self.peer_hello: Hello | None = None
        #: MAVLink system id the peer's hello came from
        self.peer_system_id: int | None = None
        self.peer_heartbeat: Heartbeat | None = None
        #: the peer's PRESSOR_REFUSAL (reason, text), once one arrived; waits then raise
        #: :class:`PeerRefused`
        self.peer_refusal: tuple[int, str] | None = None
        self._hello: Hello | None = None
        #: handlers per message id: called with the field values in XML order (messages without
        #: arrays or strings) or with the message object (the hello)
        self._handlers: dict[int, Callable[[Any], None]] = {
            _ID_HEARTBEAT: self._on_heartbeat,
            _ID_HELLO: self._on_hello,
            _ID_REFUSAL: self._on_refusal,
        }

    # ------------------------------------------------------------------ sending
    def send(self, msg: Any, *, flush: bool = True) -> bytes:
        """Pack (and sign) a generated message object, queue it, and write the queue if ``flush``.

        Returns the frame's bytes.
        """
        return self._queue(self.codec.pack(msg), flush)

    def send_fields(self, msgid: int, *values: Any, flush: bool = True) -> bytes:
        """Pack (and sign) message ``msgid`` from its field values in XML order, queue it, and
        write the queue if ``flush``; byte-identical to :meth:`send` of the generated message.
        """
        return self._queue(self.codec.pack_fields(msgid, values), flush)

    def _queue(self, frame: bytes, flush: bool) -> bytes:
        """Queue, count and log a packed ``frame``; write the queue if ``flush``."""
        self._tx += frame
        c = self.counters
        c.frames_sent += 1
        c.bytes_sent += len(frame)
        if self.tlog is not None:
            self.tlog.write(frame, self.clock())
        if flush:
            self.flush()
        return frame

    def flush(self) -> None:
        """Write queued frames to the port in one write (one syscall, one pty wake-up)."""
        if self._tx:
            data = bytes(self._tx)
            self._tx.clear()
            try:
                self.port.write(data)
            except (serial.SerialException, OSError) as exc:
                self.closed = True
                raise LinkClosedError(str(exc)) from exc

    def discard_queued(self) -> None:
        """Drop frames queued by ``flush=False`` sends (a simulated link that went down)."""
        self._tx.clear()

    def reset_session(self) -> None:
        """Forget received bytes and number frames from 0 again (a simulated reconnection; the
        peer sees a sequence gap)."""
        self.codec.restart()

    def send_hello(self, hello: Hello, *, flush: bool = True) -> None:
        """Announce this end (scenario / controller, seed, period, noise, length, mode, drug,
        concentration, pump maximum)."""
        self._hello = hello
        self.send(
            self.codec.mav.pressor_hello_encode(
                hello.sample_period_s,
                hello.patient_seed,
                hello.n_ticks,
                hello.sensor_noise_mmhg,
                self.ROLE,
                hello.link_mode,
                hello.protocol_version,
                hello.name.encode("ascii", "replace")[:32],
                hello.drug.encode("ascii", "replace")[:16],
                hello.concentration_ug_ml,
                hello.pump_max_ml_h,
            ),
            flush=flush,
        )

    def send_heartbeat(self, tick: int, state: int, *, flush: bool = True) -> None:
        """Send a heartbeat (last tick handled, ``STATE_*``), preceded by the standard MAVLink
        HEARTBEAT so generic ground tools see this node (docs/PROTOCOL.md)."""
        self.send_fields(
            _ID_STD_HEARTBEAT,
            self.MAV_TYPE,
            mavlink.MAV_AUTOPILOT_INVALID,
            0,
            state,  # custom_mode: the PRESSOR_STATE
            _MAV_STATE[state],
            3,  # mavlink_version, as the standard asks
            flush=False,
        )
        self.send_fields(_ID_HEARTBEAT, tick, self.ROLE, state, flush=flush)

    def refuse(self, refusal: HelloRefused, *, fault: bool = True) -> None:
        """Tell the peer why its hello is refused: PRESSOR_REFUSAL (reason, this end's protocol
        version, the text cut to 200 ASCII characters), then a heartbeat FAULT, written at once.
        The caller then closes the link (docs/PROTOCOL.md, "Refusals"). ``fault=False``: the
        refusal alone (a hello in the middle of a run, refused while the run goes on)."""
        text = refusal.text.encode("ascii", "replace")[:REFUSAL_TEXT_CHARS]
        self.send(
            self.codec.mav.pressor_refusal_encode(refusal.reason, PROTOCOL_VERSION, text),
            flush=not fault,
        )
        if fault:
            self.send_heartbeat(0, STATE_FAULT)

    # ---------------------------------------------------------------- receiving
    def poll(self, timeout_s: float = 0.0) -> int:
        """Read what the port has (waiting up to ``timeout_s`` for a first byte) and process it.

        Returns the number of frames accepted.
        """
        before = self.counters.frames_received
        now = time.monotonic()
        deadline = now + timeout_s
        while True:
            if self._read_once(timeout_s > 0, deadline - now):
                return self.counters.frames_received - before
            if (now := time.monotonic()) >= deadline:
                return self.counters.frames_received - before

    def _read_once(self, block: bool, timeout_s: float) -> bool:
        port = self.port
        try:
            if self._read_some is not None:  # tty hot path: one read for all that is there
                data = self._read_some(timeout_s if block else 0.0)
            else:
                n = port.in_waiting
                if n:
                    data = port.read(n)
                elif block:
                    data = port.read(1)
                else:
                    return False
        except (serial.SerialException, OSError) as exc:
            self.closed = True
            raise LinkClosedError(str(exc)) from exc
        if data:
            self.feed(data)
            return True
        return False

    def _wait(self, ready: Any, timeout_s: float) -> Any:
        """Read until ``ready()`` returns something or ``timeout_s`` (s, wall clock) passed (a
        timeout is counted and abandons a stalled partial frame)."""
        result = ready()
        if result is not None:
            return result
        now = time.monotonic()
        deadline = now + timeout_s
        while True:
            if self._read_once(True, deadline - now):
                if self.peer_refusal is not None:
                    raise PeerRefused(*self.peer_refusal, self.PEER_NAME)
                result = ready()
                if result is not None:
                    return result
            elif (now := time.monotonic()) >= deadline:
                self.counters.timeouts += 1
                if self.codec.drop_stalled():
                    self.feed(b"")
                return ready()

    def feed(self, data: bytes) -> None:
        """Process received bytes: frame, decode, check, count, log and dispatch."""
        self.codec.scan(data, self._accept)

    def _accept(self, msgid: int, payload: Any, fast: bool, frame: bytearray) -> None:
        """Dispatch an accepted frame to its handler and ``on_message``, and log it."""
        handler = self._handlers.get(msgid)
        if handler is not None:
            handler(payload)
        if self.on_message is not None:
            self.on_message(message_object(msgid, payload) if fast else payload)
        if self.tlog is not None:
            self.tlog.write(frame, self.clock())

    def _on_heartbeat(self, fields: tuple) -> None:
        tick, _role, state = fields
        self.peer_heartbeat = Heartbeat(tick, state)

    def _on_refusal(self, msg: Any) -> None:
        self.peer_refusal = (int(msg.reason), field_text(msg.text))

    def _on_hello(self, msg: Any) -> None:
        self.peer_system_id = msg.get_srcSystem()
        self.peer_hello = hello_of(msg)

    # ---------------------------------------------------------------- handshake
    def wait_for_hello(self, timeout_s: float) -> Hello | None:
        """Wait for the peer's hello (``None`` on timeout).

        Raises
        ------
        SigningMismatch
            At the first frame showing the peer signs differently (:meth:`check_signing`).
        """

        def ready() -> Hello | None:
            self.check_signing()
            return self.peer_hello

        return self._wait(ready, timeout_s)

    def check_signing(self) -> None:
        """Raise :class:`SigningMismatch` naming the cause if a received frame showed that the
        peer signs differently from this end (unsigned, another key, stale timestamps, or signed
        while this end has no key: :func:`pressor.link.handshake.signing_mismatch`)."""
        codec = self.codec
        why = signing_mismatch(self.PEER_NAME, codec.refusal, codec.peer_signed)
        if why is not None:
            raise SigningMismatch(why)

    def handshake(self, hello: Hello, timeout_s: float = 10.0, resend_s: float = 0.5) -> Hello:
        """Establish the link after both ends opened their ports; return the peer's hello.

        How the hellos are exchanged is the role's (:meth:`_exchange_hellos`).

        Raises
        ------
        LinkError
            No hello within ``timeout_s`` (s, wall clock); :class:`SigningMismatch` at once when
            the peer signs differently (after a PRESSOR_REFUSAL ``SIGNING`` sent back, so that the
            peer names it too); :class:`PeerRefused` when the peer refused this end's
            hello.
        HelloRefused
            The peer's hello announces the wrong role, comes from a system id other than its role
            or carries another protocol version (:func:`pressor.link.handshake.check_peer_hello`); the
            peer has been sent the refusal (:meth:`refuse`).
        """
        try:
            peer = self._exchange_hellos(hello, timeout_s, resend_s)
            self.check_signing()
        except SigningMismatch as exc:
            # told, signed as this end signs: a peer that checks signatures names the mismatch
            # on this very frame, one that does not reads the reason; neither waits out its
            # handshake for a hello (a hello would tell the second one the link is up)
            with suppress(LinkError):
                self.refuse(HelloRefused(REFUSAL_SIGNING, str(exc)))
            raise
        if peer is None:
            raise LinkError(f"no hello from the {self.PEER_NAME} within {timeout_s} s")
        try:
            check_peer_hello(peer, self.peer_system_id, self.PEER_NAME, self.PEER_ROLE)
        except HelloRefused as exc:
            self.refuse(exc)  # the peer is told why before its owner closes the link
            raise
        return peer

    def _exchange_hellos(self, hello: Hello, timeout_s: float, resend_s: float) -> Hello | None:
        """Send ``hello`` and wait for the peer's; ``None`` if none came within ``timeout_s``."""
        raise NotImplementedError

    # ----------------------------------------------------------------- misc
    def snapshot(self) -> LinkCounters:
        """A copy of the counters."""
        return replace(self.counters)

    def close(self) -> None:
        """Flush and close the port (idempotent); the tlog is left to its owner."""
        if not self.closed:
            try:
                self.flush()
            except LinkClosedError:
                pass
            self.closed = True
        try:
            self.port.close()
        except (serial.SerialException, OSError):
            pass
