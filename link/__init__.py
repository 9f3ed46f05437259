"""The serial link between the controller runtime and the pump/patient device (MAVLink 2).

Modules
-------
``pressor.xml``
    The dialect (message ids 45000-45006, a block no dialect in pymavlink's ``all`` uses).
``dialect/pressor.py``
    The module mavgen generates from it (committed; ``python -m link.generate``).
``transport``
    Ports: :func:`open_port` (pyserial URL or device path), :class:`PtyPair` (raw pty pair; the
    leader as an :class:`FdPort`, the follower path for pyserial in another process),
    :func:`loop_pair` (two crossed ``loop://`` ports, in-process), :class:`FaultyPort` (corrupt /
    drop every N-th write, seeded).
``endpoint``
    :class:`LinkEndpoint` - framing with resynchronisation, counters, signing, lockstep helpers.
``tlog``
    :class:`TlogWriter` (.tlog with run-clock timestamps), :func:`read_tlog`,
    :func:`register_dialect_with_mavutil`.

Runtime side (what the loop uses)
---------------------------------
::

    from link import LinkEndpoint, Hello, Signing, PtyPair, MODE_AUTO

    pty = PtyPair.open()                          # device process opens pty.follower_path
    ep = LinkEndpoint(pty.leader_port(), "runtime", signing=Signing.from_file(key), tlog=tlog)
    peer = ep.handshake(Hello("pi"), timeout_s=10)  # -> device Hello: name (scenario),
                                                  #    patient_seed, sample_period_s,
                                                  #    sensor_noise_mmhg, n_ticks, link_mode
    while True:
        x = ep.wait_for_sample(timeout_s=1.0)     # TickInputs or None (timeout, counted)
        if x is None: ...                         # watchdog; check ep.peer_heartbeat for FINISHED
        u = controller.step(x.map_mmhg, x.target_mmhg, x.K, x.T_s, x.tau_s)
        ep.send_command(x.tick, u, MODE_AUTO)     # answers tick x.tick; flushes
        ep.pump_status                            # PumpStatusMsg of the previous tick (or None)
    ep.counters                                   # LinkCounters (live); ep.snapshot() copies

``TickInputs``: ``tick, sim_time_s, map_mmhg, quality, target_mmhg, K, T_s, tau_s, sched_valid,
sched_tick, target_tick`` (the last two differ from ``tick`` when those frames were lost and the
values are stale). ``ep.peer_heartbeat`` is ``(tick, state)`` with ``STATE_FINISHED`` when the device
reached the end of its run (it then closes the link: waits raise :class:`LinkClosedError`).
After the last tick keep reading (``poll``) until that FINISHED heartbeat: a lost final command
is retransmitted-for by the device and answered by the endpoint itself. In lockstep a sample whose
scheduling/target frames were lost is withheld (``counters.incomplete_ticks``) until the device
resends the tick. Real-time loops use ``ep.poll(0)`` then ``ep.newest_sample()`` (non-blocking;
``next_sample()`` takes the oldest). Call ``PtyPair.close_follower()`` once the device process has
opened the follower, or the leader never sees the device exit. ``ep.clock`` is the run clock (by default it follows the samples' sim time; pass ``clock=`` to use
another, e.g. the monotonic clock in real-time mode). ``ep.poll(timeout_s)`` processes whatever
arrived without waiting for a sample.

Device side: ``ep.handshake(Hello(scenario, seed, Ts, noise, n_ticks), ...)``,
``ep.send_observation(obs)`` / ``send_tick(...)``, ``ep.wait_for_command(tick, timeout_s)`` ->
``Command(tick, rate_ml_h, mode)``, ``ep.send_pump_status(...)``, ``ep.send_heartbeat(...)``.

Values are float32 on the wire (sim time is double), matching ``hil_sim.world``'s rounding.
"""

from link.endpoint import (
    LINK_LOCKSTEP,
    LINK_REALTIME,
    MODE_AUTO,
    MODE_MANUAL,
    MODE_SAFE,
    MODE_STOP,
    PROTOCOL_VERSION,
    ROLE_DEVICE,
    ROLE_RUNTIME,
    STATE_BOOT,
    STATE_FAULT,
    STATE_FINISHED,
    STATE_RUNNING,
    Command,
    Hello,
    LinkClosedError,
    LinkCounters,
    LinkEndpoint,
    LinkError,
    ManualClock,
    PumpStatusMsg,
    Signing,
    TickInputs,
)
from link.tlog import TlogWriter, read_tlog, register_dialect_with_mavutil
from link.transport import (
    CrossedPort,
    FaultyPort,
    FdPort,
    PtyPair,
    loop_pair,
    open_port,
)

__all__ = [
    "LINK_LOCKSTEP",
    "LINK_REALTIME",
    "MODE_AUTO",
    "MODE_MANUAL",
    "MODE_SAFE",
    "MODE_STOP",
    "PROTOCOL_VERSION",
    "ROLE_DEVICE",
    "ROLE_RUNTIME",
    "STATE_BOOT",
    "STATE_FAULT",
    "STATE_FINISHED",
    "STATE_RUNNING",
    "Command",
    "CrossedPort",
    "FaultyPort",
    "FdPort",
    "Hello",
    "LinkClosedError",
    "LinkCounters",
    "LinkEndpoint",
    "LinkError",
    "ManualClock",
    "PtyPair",
    "PumpStatusMsg",
    "Signing",
    "TickInputs",
    "TlogWriter",
    "loop_pair",
    "open_port",
    "read_tlog",
    "register_dialect_with_mavutil",
]
