"""``pressor device``: the simulated pump / patient monitor on a serial port.

Wraps :class:`pressor.hil_sim.world.World` (the pure core) in the link protocol of :mod:`link`:

1. open the port (a pyserial URL or device path, e.g. the follower of the pty ``pressor sil``
   created, or one end of a ``socat`` pair), handshake: announce itself with a hello (scenario,
   patient seed, sample period, sensor noise, number of ticks, link mode, and the syringe:
   ``--drug``, ``--concentration-ug-ml``, the pump's maximum rate) every 0.5 s until the runtime
   answers; the patient is ``--patient-model`` (:mod:`pressor.hil_sim.patients.patient_model`, default the
   paper's);
2. per tick k (lockstep, PX4 SITL style): send tick k's scheduling parameters, target and MAP sample
   (plus a heartbeat once per simulated second), wait for the infusion command answering tick k,
   apply it, advance the world one sample period, queue the pump status (it leaves with the next
   tick's frames: one write, one pty wake-up per tick). A tick whose command does not arrive within
   ``--retransmit`` seconds (wall) is sent again; after ``--link-timeout`` seconds without an answer
   the device gives up (heartbeat FAULT, exit 1);
3. at the end of ``--duration`` send a FINISHED heartbeat and close; a runtime that closes the link
   first ends the run too (exit 0, reported on stderr).

``--realtime`` runs on the wall clock instead: tick k is released at t0 + k·Ts (absolute deadlines),
the command answering it is applied if it arrived before the next release, otherwise the pump keeps
the previous rate (counted as a timeout). A monitor slower than the tick (scenario
``sensor.period_s``) sends MAP_SAMPLE only when it has a new value: in lockstep every tick carries
one, the value repeated with ``QUALITY_HELD`` between updates; in real time the ticks between
updates carry none, and the runtime's command for each of them answers the latest sample sent
(docs/PROTOCOL.md, sample-and-hold).

Faults (``--fault KIND[:ARGS]``, repeatable; see ``pressor faults`` and :mod:`pressor.contracts.faults`):
sensor, pump and scheduling faults are injected in the world (:mod:`pressor.hil_sim.scenarios.faults`);
byte-level link faults by a wrapper of the port; ``link-stall`` / ``link-disconnect`` by this loop: during
the window the device keeps simulating (the pump holds its last rate until its own watchdog trips)
but sends nothing and waits for nothing, so the runtime sees a jump in sim time and runs its
watchdogs over the silent ticks on its virtual clock. A disconnect also cuts the burst in flight
mid-frame, loses what was queued or received, and reconnects as a new session (hello, sequence
numbers from 0). The runtime learns of a fault only through what arrives on the link.

Sim time comes from the device. The run clock used for signing timestamps and the .tlog is the
world's sim time, so a lockstep run is byte-for-byte reproducible.

Exit codes: 0 run completed (or the runtime closed the link), 1 link lost / handshake failed,
2 bad usage or input, or a hello refused (PRESSOR_REFUSAL: one line with the reason).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pressor.contracts.checks import check_range
from pressor.contracts.controller import DESIGN_CONCENTRATION_UG_ML, DESIGN_DRUG
from pressor.hil_sim.devices.device_options import (
    HANDSHAKE_TIMEOUT_S,
    LINK_TIMEOUT_S,
    RETRANSMIT_S,
    device_parser,
    make_world,
)
from pressor.plumbing.usage import UsageError, run_command
from pressor.runtime.shell.interrupt import begin_run, exit_code, signal_name, stop_requested
from pressor.runtime.shell.placement import pin_thread

if TYPE_CHECKING:  # numpy: imported when a run keeps the true MAP, not for --help
    from pressor.hil_sim.patients.truth import TruthLog


@dataclass(frozen=True)
class DeviceResult:
    """What a device run did: ticks completed, how it ended, link counters."""

    ticks: int
    ended: str
    counters: dict[str, int]


def main(command: str, argv: list[str]) -> int:
    """Entry point of ``pressor device`` (see the module docstring)."""
    from pressor.runtime.shell.interrupt import stop_on_signals

    with stop_on_signals():
        return run_command(f"pressor {command}", lambda args: _main(command, args), argv)


def _main(command: str, argv: Sequence[str]) -> int:
    args = device_parser(command).parse_args(argv)
    usage = UsageError  # an option out of range is the user's error: exit 2, one line
    check_range("--rate", args.rate, 0.0, 1000.0, lo_open=True, unit="Hz", error=usage)
    if args.duration is not None:
        days30 = 30 * 24 * 3600.0
        check_range("--duration", args.duration, 0.0, days30, lo_open=True, unit="s", error=usage)
    check_range("--patient-seed", args.patient_seed, 0, 2**32 - 1, error=usage)
    for opt in ("retransmit", "link_timeout", "handshake_timeout"):
        name = f"--{opt.replace('_', '-')}"
        check_range(name, getattr(args, opt), 0.0, 3600.0, lo_open=True, unit="s", error=usage)
    if args.pump_max_ml_h is not None:
        pump = args.pump_max_ml_h
        check_range("--pump-max-ml-h", pump, 0.0, 10000.0, lo_open=True, unit="ml/h", error=usage)
    faults = _parse_faults(args.fault)
    pin_thread(args.cpu)  # the lockstep ends on their CPUs (pressor.runtime.shell.placement)
    world = make_world(args, faults)

    from pressor.link import (
        DeviceSession,
        LinkClosedError,
        LinkError,
        ManualClock,
        Refusal,
        TlogWriter,
        fast_port,
        open_port,
    )

    # the key first: a bad key file is refused (exit 2, one line naming it) before any port opens
    signing = _load_signing(args.signing_key, args.no_signing, f"pressor {command}")
    begin_run()  # from here a stop signal is graceful (FINISHED heartbeat, .tlog kept)
    try:
        port = fast_port(open_port(args.port))
    except Exception as exc:  # pyserial raises SerialException / ValueError for bad URLs
        raise UsageError(f"--port: cannot open {args.port!r}: {exc}") from None
    from pressor.hil_sim.scenarios.faults import LinkFaultPort, LinkFaults

    link_faults = LinkFaults(world.fault_specs, world.sample_period_s)
    if link_faults.bytewise or link_faults.down:
        port = LinkFaultPort(port, link_faults, lambda: world.tick)
    tlog = TlogWriter(args.tlog) if args.tlog else None
    clock = ManualClock()
    ep = DeviceSession(port, signing=signing, clock=clock, tlog=tlog)
    from pressor.hil_sim.patients.truth import TruthLog

    truth = TruthLog() if args.truth_out else None
    ok = False
    try:
        result = run_device(
            ep,
            world,
            clock,
            duration_s=args.duration,
            realtime=args.realtime,
            retransmit_s=args.retransmit,
            link_timeout_s=args.link_timeout,
            handshake_timeout_s=args.handshake_timeout,
            link_faults=link_faults,
            drug=args.drug,
            concentration_ug_ml=args.concentration_ug_ml,
            truth=truth,
        )
        ok = True
    except LinkClosedError:
        result = DeviceResult(world.tick, "runtime closed the link", ep.counters.as_dict())
        ok = True
    except LinkError as exc:  # a refused hello exits 2 (either end told the other why)
        print(f"pressor {command}: {exc}", file=sys.stderr)
        return 2 if isinstance(exc, Refusal) else 1
    finally:
        ep.close()
        if tlog is not None:
            tlog.close(commit=ok)  # a failed run never clobbers an earlier .tlog
        if truth is not None:
            truth.save(args.truth_out)  # whatever happened: the ticks played so far
    print(f"pressor {command}: {result.ended} after {result.ticks} ticks", file=sys.stderr)
    if (stop := stop_requested()) is not None and result.ended.startswith("interrupted"):
        return exit_code(stop)
    return 0 if result.ended in ("completed", "runtime closed the link") else 1


def _parse_faults(texts: list[str]) -> tuple:
    from pressor.contracts.faults import FaultSpecError, parse_faults

    try:
        return tuple(parse_faults(texts))
    except FaultSpecError as exc:
        raise UsageError(str(exc)) from exc


def _load_signing(path: str | None, no_signing: bool, prog: str) -> Any:
    """The device's signing (``None`` with ``--no-signing``, warned); a key file readable by
    every user or all zeros is warned on stderr (:func:`pressor.link.signing.key_file_warnings`)."""
    from pressor.link.signing import Signing, default_key_path, key_file_warnings

    if no_signing:
        if path is not None:
            raise UsageError("--no-signing and --signing-key: choose one")
        print(f"{prog}: warning: the link is unsigned (--no-signing)", file=sys.stderr)
        return None
    if path is None:
        path = str(default_key_path())
        if not Path(path).exists():
            raise UsageError(
                f"--signing-key: no key at the default {path}: make one with 'pressor keygen'"
                " (the runtime needs the same file), or pass --no-signing"
            )
    try:
        signing = Signing.from_file(path)
    except OSError as exc:
        raise UsageError(f"--signing-key: cannot read {path}: {exc.strerror}") from exc
    except ValueError as exc:
        raise UsageError(f"--signing-key: {exc}") from exc
    for line in key_file_warnings(path, signing.key):
        print(f"{prog}: warning: {line}", file=sys.stderr)
    return signing


def run_device(
    ep: Any,
    world: Any,
    clock: Any,
    *,
    duration_s: float | None = None,
    realtime: bool = False,
    retransmit_s: float = RETRANSMIT_S,
    link_timeout_s: float = LINK_TIMEOUT_S,
    handshake_timeout_s: float = HANDSHAKE_TIMEOUT_S,
    link_faults: Any = None,
    drug: str = DESIGN_DRUG,
    concentration_ug_ml: float = DESIGN_CONCENTRATION_UG_ML,
    truth: TruthLog | None = None,
) -> DeviceResult:
    """Run ``world`` as the device end of the link ``ep`` (handshake included).

    Parameters
    ----------
    ep
        A :class:`link.DeviceSession` whose clock is ``clock``.
    world
        A fresh :class:`pressor.hil_sim.world.World`.
    clock
        The session's :class:`link.ManualClock`; set to the world's sim time (s).
    duration_s
        Simulated time (s); default the scenario's duration. ``round(duration / Ts)`` ticks.
    realtime
        Wall-clock mode instead of lockstep.
    retransmit_s, link_timeout_s, handshake_timeout_s
        Wall-clock timeouts (s), see the module docstring.
    link_faults
        :class:`pressor.hil_sim.scenarios.faults.LinkFaults` whose stalls/disconnects this loop plays (the
        byte-level ones live in the port wrapper).
    drug, concentration_ug_ml
        The syringe the hello announces (µg/ml), with the world's pump maximum (ml/h).
    truth
        Where to keep each tick's true MAP (:mod:`pressor.hil_sim.patients.truth`; sized here for the run), or
        ``None``.

    Returns
    -------
    DeviceResult

    Raises
    ------
    link.LinkClosedError
        The runtime closed the link.
    link.LinkError
        The handshake failed.
    """
    from pressor.contracts.faults import QUALITY_HELD
    from pressor.link import (
        LINK_LOCKSTEP,
        LINK_REALTIME,
        MODE_STOP,
        STATE_FAULT,
        STATE_FINISHED,
        STATE_RUNNING,
        Hello,
        LinkError,
        Refusal,
        SigningMismatch,
    )

    ts = world.sample_period_s
    duration = world.scenario.duration_s if duration_s is None else duration_s
    n = int(round(duration / ts))
    if truth is not None:
        truth.reserve(n)
    hello = Hello(
        world.scenario.name,
        world.patient_seed,
        ts,
        float(world.scenario.sensor.noise_std_mmhg),
        n,
        LINK_REALTIME if realtime else LINK_LOCKSTEP,
        drug=drug,
        concentration_ug_ml=concentration_ug_ml,
        pump_max_ml_h=world.pump.config.max_rate_ml_h,
    )
    deadline = time.monotonic() + handshake_timeout_s
    while True:  # short attempts (a hello each): a stop signal is noticed within 0.5 s
        if (stop := stop_requested()) is not None:
            return DeviceResult(0, f"interrupted by {signal_name(stop)}", ep.counters.as_dict())
        try:
            ep.handshake(hello, timeout_s=min(0.5, max(0.0, deadline - time.monotonic())))
            break
        except LinkError as exc:  # wrong role, system id or protocol: the runtime was told
            if ep.peer_hello is not None or isinstance(exc, (SigningMismatch, Refusal)):
                raise  # or the runtime refused this device, or signs differently
            if time.monotonic() >= deadline:
                raise LinkError(
                    f"no hello from the runtime within {handshake_timeout_s} s"
                ) from None
    hb_every = max(1, int(round(1.0 / ts)))
    observe, apply_command, advance = world.observe, world.apply_command, world.advance
    send_obs, wait_cmd, send_status = ep.send_tick, ep.wait_for_command, ep.send_pump_status
    t0 = time.monotonic()
    down = link_faults.link_down if link_faults is not None and link_faults.down else None
    answers = 0  # real time: the tick of the latest sample sent, which the runtime answers
    for k in range(n):
        if (stop := stop_requested()) is not None:
            ep.send_heartbeat(k, STATE_FINISHED)  # the runtime ends its run cleanly
            return DeviceResult(k, f"interrupted by {signal_name(stop)}", ep.counters.as_dict())
        clock.t = world.sim_time_s
        obs = observe()
        if truth is not None:
            truth.record(k, obs.sim_time_s, world.true_map_mmhg(), world.pump.delivered_ml_h)
        if down is not None and _link_down_tick(ep, world, link_faults, k, obs, hello):
            if realtime:
                _sleep_until(ep, t0 + (k + 1) * ts)
            status = advance()  # no command arrives: the pump keeps its rate and its watchdog
            clock.t = world.sim_time_s
            if link_faults.link_down(k + 1) is None:  # leaves with the first tick after the gap
                send_status(status, flush=False)
            continue
        if k % hb_every == 0:
            ep.send_heartbeat(k, STATE_RUNNING, flush=False)
        if realtime:
            _sleep_until(ep, t0 + k * ts)
            new_sample = k == 0 or not obs.quality & QUALITY_HELD
            answers = k if new_sample else answers
            send_obs(obs, sample=new_sample)
            cmd = wait_cmd(answers, max(0.0, t0 + (k + 1) * ts - time.monotonic()))
        else:
            send_obs(obs)
            cmd = wait_cmd(k, retransmit_s)
            waited = retransmit_s
            while cmd is None and stop_requested() is None:
                if waited >= link_timeout_s:
                    ep.send_heartbeat(k, STATE_FAULT)
                    return DeviceResult(k, "no command from the runtime", ep.counters.as_dict())
                ep.counters.retransmits += 1
                send_obs(obs)
                cmd = wait_cmd(k, retransmit_s)
                waited += retransmit_s
        # Only a command that arrived reaches the pump: re-applying the last one on a silent tick
        # would feed the pump's own watchdog and defeat it (defence in depth, real-time mode).
        if cmd is not None:
            apply_command(0.0 if cmd.mode == MODE_STOP else cmd.rate_ml_h)
        status = advance()
        clock.t = world.sim_time_s
        send_status(status, flush=False)
    if realtime:
        _sleep_until(ep, t0 + n * ts)
    ep.send_heartbeat(n, STATE_FINISHED)
    return DeviceResult(n, "completed", ep.counters.as_dict())


def _link_down_tick(ep: Any, world: Any, faults: Any, k: int, obs: Any, hello: Any) -> bool:
    """Play tick ``k`` of a stall/disconnect; return True if the link is down at ``k``.

    On the first tick of a window what is queued is lost (a disconnect cuts the burst in flight
    mid-frame); on the first tick after a disconnect the device reconnects as a new session.
    """
    spec = faults.link_down(k)
    ended = faults.ends_at(k)
    if spec is None:
        if ended is not None and ended.kind == "link-disconnect":
            ep.reset_session()  # what arrived while unplugged is gone; sequence from 0
            ep.send_hello(hello, flush=False)
        return False
    if faults.starts_at(k) is spec:
        if spec.kind == "link-disconnect" and hasattr(ep.port, "cut_next_write"):
            ep.send_tick(obs, flush=False)
            ep.port.cut_next_write = True
            ep.flush()
        else:
            ep.discard_queued()  # the queued pump status never leaves
    return True


def _sleep_until(ep: Any, deadline: float) -> None:
    """Process incoming frames until the wall clock reaches ``deadline`` (monotonic s)."""
    while True:
        left = deadline - time.monotonic()
        if left <= 0.0:
            return
        if left > 0.015:  # a port read may block ~10 ms past its timeout: stop polling early
            ep.poll(left - 0.012)
        else:
            ep.flush()
            time.sleep(left)
