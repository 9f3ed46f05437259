"""The serial link between the controller runtime and the pump/patient device (MAVLink 2).

Both ends speak it: the runtime (``runtime``) and the simulated device (``pressor.hil_sim.devices.device``). It
imports no other package of this project.

Modules
-------
``pressor.xml``
    The dialect (message ids 45000-45007, a block no dialect in pymavlink's ``all`` uses).
``dialect/pressor.py``
    The module mavgen generates from it (committed; ``python -m pressor.link.generate``).
``messages``
    One typed message per frame, the same on both ends: :class:`Hello`, :class:`Heartbeat`,
    :class:`TickInputs` (a tick's scheduling, target and MAP frames), :class:`Command`,
    :class:`PumpStatus`; the dialect's enums (``MODE_*``, ``STATE_*``, ``LINK_*``, ``ROLE_*``,
    ``REFUSAL_*``).
``codec``
    :class:`~pressor.link.codec.FrameCodec` - framing with resynchronisation, CRC, sequence and signature
    checks, the fast pack/decode path.
``counters``, ``signing``
    :class:`LinkCounters` (``DROP_CAUSES``: the ones counting what is dropped, by cause),
    :class:`LinkError`, :class:`LinkClosedError`, :class:`SigningMismatch`,
    :class:`HelloRefused` (this end refuses the peer's hello), :class:`PeerRefused` (the peer
    refused ours), both a :class:`Refusal`; :class:`Signing`, :func:`~pressor.link.signing.default_key_path`.
``session``, ``runtime_session``, ``device_session``
    :class:`Session` (what both ends share: hellos, handshake, heartbeats, reading, dispatch),
    :class:`RuntimeSession` (assembles ticks, sends commands), :class:`DeviceSession` (sends ticks
    and pump status, waits for commands); :class:`ManualClock`.
``ports``, ``ttyport``
    :func:`open_port` (pyserial URL or device path), :class:`PortWrapper`; :class:`PtyPair` (raw
    pty pair; the leader as an :class:`FdPort`, the follower path for pyserial in another process),
    :func:`fast_port` (the tty hot path of a posix pyserial port).
``tlog``
    :class:`TlogWriter` (.tlog with run-clock timestamps), :func:`read_tlog`,
    :func:`register_dialect_with_mavutil`.

Runtime side (what the loop uses)
---------------------------------
::

    from pressor.link import RuntimeSession, Hello, Signing, PtyPair, MODE_AUTO

    pty = PtyPair.open()                          # device process opens pty.follower_path
    ep = RuntimeSession(pty.leader_port(), signing=Signing.from_file(key), tlog=tlog)
    peer = ep.handshake(Hello("pi"), timeout_s=10)  # -> device Hello: name (scenario),
                                                  #    patient_seed, sample_period_s,
                                                  #    sensor_noise_mmhg, n_ticks, link_mode
    while True:
        x = ep.wait_for_sample(timeout_s=1.0)     # TickInputs or None (timeout, counted)
        if x is None: ...                         # watchdog; check ep.peer_heartbeat for FINISHED
        u = controller.step(x.map_mmhg, x.target_mmhg, x.K, x.T_s, x.tau_s)
        ep.send_command(x.tick, u, MODE_AUTO)     # answers tick x.tick; flushes
        ep.pump_status                            # PumpStatus of the previous tick (or None)
    ep.counters                                   # LinkCounters (live); ep.snapshot() copies

``TickInputs``: ``tick, sim_time_s, map_mmhg, quality, target_mmhg, K, T_s, tau_s, sched_valid,
sched_tick, target_tick`` (the last two differ from ``tick`` when those frames were lost and the
values are stale). ``ep.peer_heartbeat`` is a :class:`Heartbeat` ``(tick, state)`` with
``STATE_FINISHED`` when the device reached the end of its run (it then closes the link: waits raise
:class:`LinkClosedError`). After the last tick keep reading (``poll``) until that FINISHED
heartbeat: a lost final command is retransmitted-for by the device and answered by the session
itself. In lockstep a tick is handed over once complete, its frames in any order (the sample waits
for the tick's required scheduling/target frames and its pump status); one whose frames were lost
is withheld until the device resends it (``counters.incomplete_sched`` / ``_target`` /
``_status``; everything dropped is counted by cause, ``DROP_CAUSES``). Real-time loops use
``ep.poll(0)`` then ``ep.newest_sample()`` (non-blocking; ``next_sample()`` takes the oldest). Call
``PtyPair.close_follower()`` once the device process has opened the follower, or the leader never
sees the device exit. ``ep.clock`` is the run clock (by default it follows the samples' sim time;
pass ``clock=`` to use another, e.g. the monotonic clock in real-time mode). ``ep.poll(timeout_s)``
processes whatever arrived without waiting for a sample.

Device side: ``DeviceSession(port, clock=ManualClock())``, ``ep.handshake(Hello(scenario, seed,
Ts, noise, n_ticks), ...)``, ``ep.send_tick(world.observe())`` (a :class:`TickInputs`),
``ep.wait_for_command(tick, timeout_s)`` -> :class:`Command` ``(tick, rate_ml_h, mode)``,
``ep.send_pump_status(world.advance())`` (a :class:`PumpStatus`), ``ep.send_heartbeat(...)``.

Values are float32 on the wire (sim time is double), matching ``pressor.hil_sim.world``'s rounding.
"""

from pressor.link.counters import (
    DROP_CAUSES,
    HelloRefused,
    LinkClosedError,
    LinkCounters,
    LinkError,
    PeerRefused,
    Refusal,
    SigningMismatch,
)
from pressor.link.device_session import DeviceSession
from pressor.link.messages import (
    LINK_LOCKSTEP,
    LINK_REALTIME,
    MODE_AUTO,
    MODE_MANUAL,
    MODE_SAFE,
    MODE_STOP,
    PROTOCOL_VERSION,
    REFUSAL_CONCENTRATION,
    REFUSAL_DRUG,
    REFUSAL_LINK_MODE,
    REFUSAL_PROTOCOL_VERSION,
    REFUSAL_PUMP_MAXIMUM,
    REFUSAL_ROLE,
    REFUSAL_RUNTIME_CONFIG,
    REFUSAL_SAMPLE_PERIOD,
    REFUSAL_SENSOR_NOISE,
    REFUSAL_SIGNING,
    REFUSAL_SYSTEM_ID,
    ROLE_DEVICE,
    ROLE_RUNTIME,
    STATE_BOOT,
    STATE_FAULT,
    STATE_FINISHED,
    STATE_RUNNING,
    Command,
    Heartbeat,
    Hello,
    PumpStatus,
    TickInputs,
)
from pressor.link.ports import PortWrapper, open_port
from pressor.link.runtime_session import RuntimeSession
from pressor.link.session import ManualClock, Session
from pressor.link.signing import Signing
from pressor.link.tlog import TlogWriter, read_tlog, register_dialect_with_mavutil
from pressor.link.ttyport import FdPort, PtyPair, fast_port

__all__ = [
    "DROP_CAUSES",
    "LINK_LOCKSTEP",
    "LINK_REALTIME",
    "MODE_AUTO",
    "MODE_MANUAL",
    "MODE_SAFE",
    "MODE_STOP",
    "PROTOCOL_VERSION",
    "REFUSAL_CONCENTRATION",
    "REFUSAL_DRUG",
    "REFUSAL_LINK_MODE",
    "REFUSAL_PROTOCOL_VERSION",
    "REFUSAL_PUMP_MAXIMUM",
    "REFUSAL_RUNTIME_CONFIG",
    "REFUSAL_ROLE",
    "REFUSAL_SAMPLE_PERIOD",
    "REFUSAL_SENSOR_NOISE",
    "REFUSAL_SIGNING",
    "REFUSAL_SYSTEM_ID",
    "ROLE_DEVICE",
    "ROLE_RUNTIME",
    "STATE_BOOT",
    "STATE_FAULT",
    "STATE_FINISHED",
    "STATE_RUNNING",
    "Command",
    "DeviceSession",
    "FdPort",
    "Heartbeat",
    "Hello",
    "HelloRefused",
    "LinkClosedError",
    "LinkCounters",
    "LinkError",
    "ManualClock",
    "PeerRefused",
    "PortWrapper",
    "PtyPair",
    "PumpStatus",
    "Refusal",
    "RuntimeSession",
    "Session",
    "Signing",
    "SigningMismatch",
    "TickInputs",
    "TlogWriter",
    "fast_port",
    "open_port",
    "read_tlog",
    "register_dialect_with_mavutil",
]
