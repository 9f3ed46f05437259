"""An independent patient monitor + syringe pump written from docs/PROTOCOL.md alone.

It uses pymavlink and the dialect XML (``link/pressor.xml``) only: its bindings are generated with
pymavlink's mavgen at test time, and it imports nothing of the project (a test scans the imports of
both its modules). This module is its link end: dialect, key, signing, hello and the tick loop in
both link modes over a file descriptor (a pty master) while the real ``pressor run`` is the runtime
end. Its own patient (first order + transport delay), pump and monitor are in
``tests/support/protocol_device_bedside.py``.
"""

from __future__ import annotations

import importlib.util
import math
import os
import select
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

from pymavlink.generator import mavgen

from tests.support.protocol_device_bedside import Monitor, Patient, PatientModel, Pump

#: MAVLink signing epoch (2015-01-01 00:00:00 UTC) in Unix seconds.
SIGNING_EPOCH_S = 1420070400.0


def build_dialect(xml: Path, out_dir: Path) -> ModuleType:
    """Generate MAVLink 2 Python bindings from ``xml`` into ``out_dir`` and import them."""
    out = out_dir / "protodev_dialect.py"
    opts = mavgen.Opts(str(out), wire_protocol="2.0", language="Python3", validate=False)
    if not mavgen.mavgen(opts, [str(xml)]):
        raise RuntimeError(f"mavgen failed on {xml}")
    spec = importlib.util.spec_from_file_location("protodev_dialect", out)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def read_key(path: Path) -> bytes:
    """A signing key file: 32 raw bytes or 64 hex characters, whitespace ignored."""
    raw = path.read_bytes()
    if len(raw) == 32:
        return raw
    return bytes.fromhex("".join(raw.decode("ascii").split()))


def wall_signing_stamp() -> int:
    """The MAVLink signing timestamp of now: 10 us units since 2015-01-01 UTC."""
    return int((time.time() - SIGNING_EPOCH_S) * 100_000)


@dataclass
class DeviceConfig:
    """What the device plays: link mode, run length, patient, monitor, pump and the clinician."""

    realtime: bool = False
    sample_period_s: float = 0.1
    n_ticks: int = 6000
    target_mmhg: float = 70.0
    send_scheduling: bool = True
    patient: tuple[float, float, float, float] = (0.4, 120.0, 30.0, 55.0)  # K, T s, tau s, mmHg
    pump_max_ml_h: float = 120.0
    drug: str = "phenylephrine"
    concentration_ug_ml: float = 100.0
    noise_mmhg: float = 0.5
    quantum_mmhg: float | None = None
    monitor_period_s: float | None = None  # None: a new value every tick
    seed: int = 7
    key: bytes | None = None
    wall_clock_signing: bool = True  # False: stamps from 0, pymavlink's default (to be refused)
    name: str = "protodev"
    retransmit_s: float = 0.5
    link_timeout_s: float = 10.0
    handshake_timeout_s: float = 30.0
    # what the hello announces and where it comes from; the runtime refuses other values
    protocol_version: int = 2
    role: int = 2  # PRESSOR_ROLE_DEVICE
    system_id: int = 2  # = the role


@dataclass
class DeviceLog:
    """What the device saw and did, for the tests."""

    runtime_hello: Any = None
    # tick answered -> (rate ml/h, mode, arrival s after the handshake), first copy of each
    commands: dict[int, tuple[float, int, float]] = field(default_factory=dict)
    true_map_mmhg: list[float] = field(default_factory=list)
    samples: list[tuple[int, float, int]] = field(default_factory=list)  # tick, mmHg, quality
    runtime_states: list[int] = field(default_factory=list)
    commands_received: int = 0  # every INFUSION_COMMAND frame, duplicates included
    missed_commands: int = 0  # real time: ticks without their command by the next release
    resends: int = 0  # lockstep: tick resends
    refused_frames: int = 0  # frames failing the signature check or unparsable
    refusal: tuple[int, str] | None = None  # the runtime's PRESSOR_REFUSAL: reason, text
    outcome: str = ""


def hello_fields(d: ModuleType, cfg: DeviceConfig) -> dict[str, Any]:
    """The device's PRESSOR_HELLO (the one place to change when the hello grows)."""
    return {
        "sample_period_s": cfg.sample_period_s,
        "patient_seed": cfg.seed,
        "n_ticks": cfg.n_ticks,
        "sensor_noise_mmhg": cfg.noise_mmhg,
        "role": cfg.role,
        "link_mode": d.PRESSOR_LINK_MODE_REALTIME if cfg.realtime else d.PRESSOR_LINK_MODE_LOCKSTEP,
        "protocol_version": cfg.protocol_version,
        "name": cfg.name.encode("ascii"),
        "drug": cfg.drug.encode("ascii"),
        "concentration_ug_ml": cfg.concentration_ug_ml,
        "pump_max_ml_h": cfg.pump_max_ml_h,
    }


class _Out:
    """Collects a tick's frames so they leave in one write."""

    def __init__(self) -> None:
        self.buf = bytearray()

    def write(self, data: bytes) -> None:
        self.buf += data


class LinkDown(Exception):
    """The device stops: the peer ended, a timeout passed, or the link failed."""


class ProtocolDevice:
    """The device end of the pressor link over the file descriptor ``fd`` (a pty master).

    ``peer_gone`` is polled while waiting (the test harness passes "the runtime exited").
    ``patient`` replaces the device's own :class:`Patient` built from ``cfg.patient`` (stepped once
    per ``cfg.sample_period_s``); with ``cfg.send_scheduling`` it must also have ``K``, ``T_s``
    and ``tau_s``.
    """

    def __init__(
        self,
        dialect: ModuleType,
        fd: int,
        cfg: DeviceConfig,
        peer_gone: Callable[[], bool] = lambda: False,
        patient: PatientModel | None = None,
    ):
        self.d, self.fd, self.cfg, self.peer_gone = dialect, fd, cfg, peer_gone
        self.out = _Out()
        self.mav = dialect.MAVLink(self.out, srcSystem=cfg.system_id, srcComponent=1)
        self.mav.robust_parsing = True
        if cfg.key is not None:
            self.mav.signing.secret_key = cfg.key
            self.mav.signing.link_id = 0
            self.mav.signing.timestamp = wall_signing_stamp() if cfg.wall_clock_signing else 0
            self.mav.signing.sign_outgoing = True
        self.patient = Patient(*cfg.patient, cfg.sample_period_s) if patient is None else patient
        self.pump = Pump(dialect, cfg.pump_max_ml_h)
        every = round((cfg.monitor_period_s or cfg.sample_period_s) / cfg.sample_period_s)
        self.monitor = Monitor(cfg.noise_mmhg, cfg.quantum_mmhg, every, cfg.seed)
        self.heartbeat_every = round(1.0 / cfg.sample_period_s)
        self.log = DeviceLog()
        self.t_start = time.monotonic()
        self.pending: tuple[int, float, int] | None = None  # newest command not yet applied

    # -- wire ---------------------------------------------------------------------------------
    def _flush(self) -> None:
        data, self.out.buf = bytes(self.out.buf), bytearray()
        while data:
            _, ready, _ = select.select([], [self.fd], [], 1.0)
            if not ready:
                raise LinkDown("write blocked for 1 s")
            data = data[os.write(self.fd, data) :]

    def _receive(self, timeout_s: float) -> list[Any]:
        ready, _, _ = select.select([self.fd], [], [], max(0.0, timeout_s))
        if not ready:
            if self.peer_gone():
                raise LinkDown("peer gone")
            return []
        try:
            data = os.read(self.fd, 4096)
        except OSError as exc:
            raise LinkDown(f"read failed: {exc}") from exc
        msgs = []
        for m in self.mav.parse_buffer(data) or []:
            if m.get_type() == "BAD_DATA":
                self.log.refused_frames += 1
            else:
                msgs.append(m)
        return msgs

    def _handle(self, m: Any) -> None:
        kind = m.get_type()
        if kind == "INFUSION_COMMAND":
            arrived_s = time.monotonic() - self.t_start
            self.log.commands_received += 1
            self.log.commands.setdefault(m.tick, (m.rate_ml_h, m.mode, arrived_s))
            if self.pending is None or m.tick >= self.pending[0]:
                self.pending = (m.tick, m.rate_ml_h, m.mode)
        elif kind == "PRESSOR_REFUSAL":  # the runtime refused the hello; it closes the link
            self.log.refusal = (m.reason, m.text)
            raise LinkDown(f"refused by the runtime: {m.text}")
        elif kind == "PRESSOR_HEARTBEAT":
            self.log.runtime_states.append(m.state)
            if m.state == self.d.PRESSOR_STATE_FAULT:
                raise LinkDown("runtime heartbeat FAULT")

    def _pump_status(self, tick: int) -> None:
        """PUMP_STATUS numbered ``tick`` = k+1 after applying tick k's command for one period."""
        p = self.pump
        self.mav.send(self.mav.pump_status_encode(tick, p.rate_ml_h, p.volume_ml, p.alarms))

    def _heartbeat(self, tick: int, state: int) -> None:
        status = {
            self.d.PRESSOR_STATE_RUNNING: self.d.MAV_STATE_ACTIVE,
            self.d.PRESSOR_STATE_FINISHED: self.d.MAV_STATE_STANDBY,
        }.get(state, self.d.MAV_STATE_CRITICAL)
        self.mav.send(
            self.mav.heartbeat_encode(
                self.d.MAV_TYPE_GENERIC, self.d.MAV_AUTOPILOT_INVALID, 0, state, status
            )
        )
        self.mav.send(self.mav.pressor_heartbeat_encode(tick, self.d.PRESSOR_ROLE_DEVICE, state))

    # -- protocol -----------------------------------------------------------------------------
    def handshake(self) -> None:
        """Send the hello every 0.5 s until the runtime's hello arrives (or its refusal)."""
        deadline = time.monotonic() + self.cfg.handshake_timeout_s
        while self.log.runtime_hello is None:
            if time.monotonic() > deadline:
                raise LinkDown("no runtime hello")
            self.mav.send(self.mav.pressor_hello_encode(**hello_fields(self.d, self.cfg)))
            self._flush()
            resend_at = time.monotonic() + self.cfg.retransmit_s
            while self.log.runtime_hello is None and time.monotonic() < resend_at:
                msgs = self._receive(resend_at - time.monotonic())
                for i, m in enumerate(msgs):
                    if m.get_type() == "PRESSOR_HELLO":
                        self._check_runtime_hello(m, msgs[i + 1 :])
                        self.log.runtime_hello = m
                    self._handle(m)
        self.t_start = time.monotonic()

    def _check_runtime_hello(self, m: Any, read_with_it: list[Any]) -> None:
        """A runtime hello of another role or protocol version ends the run; a runtime that
        refuses this device's hello sends its refusal right after its hello: in the same read
        (``read_with_it``, the frames after the hello) or within 2 s."""
        if (
            m.role == self.d.PRESSOR_ROLE_RUNTIME
            and m.protocol_version == self.cfg.protocol_version
        ):
            return
        for later in read_with_it:
            self._handle(later)  # raises LinkDown on the refusal
        until = time.monotonic() + 2.0
        while time.monotonic() < until:
            for later in self._receive(until - time.monotonic()):
                self._handle(later)  # raises LinkDown on the refusal
        raise LinkDown(f"bad runtime hello {m}")

    def _tick_frames(self, tick: int, with_sample: bool = True) -> None:
        """Queue tick ``tick``: [pump status], [heartbeats], scheduling, target, sample last."""
        cfg = self.cfg
        if tick > 0:
            self._pump_status(tick)
        if tick % self.heartbeat_every == 0:
            self._heartbeat(tick, self.d.PRESSOR_STATE_RUNNING)
        if not with_sample:
            return
        if cfg.send_scheduling:
            pt = self.patient
            self.mav.send(self.mav.scheduling_params_encode(tick, pt.K, pt.T_s, pt.tau_s, 1))
        self.mav.send(self.mav.map_target_encode(tick, cfg.target_mmhg))
        _, value, quality = self.log.samples[-1]
        self.mav.send(self.mav.map_sample_encode(tick * cfg.sample_period_s, tick, value, quality))

    def _measure(self, tick: int) -> bool:
        """Read the monitor for ``tick``; True when the tick carries a MAP_SAMPLE.

        Between monitor updates a lockstep tick repeats the last value marked held, a real-time
        tick carries no sample.
        """
        self.log.true_map_mmhg.append(self.patient.map_mmhg)
        value, fresh = self.monitor.read(tick, self.patient.map_mmhg)
        if not fresh and self.cfg.realtime:
            return False
        if math.isnan(value):
            quality = self.d.PRESSOR_MAP_QUALITY_INVALID
        else:
            quality = 0 if fresh else self.d.PRESSOR_MAP_QUALITY_HELD
        self.log.samples.append((tick, value, quality))
        return True

    def _advance(self, command: tuple[int, float, int] | None) -> None:
        """Apply a command (tick, ml/h, mode; None: none came) and integrate one sample period."""
        stop = command is not None and command[2] == self.d.PRESSOR_COMMAND_MODE_STOP
        self.pump.apply(0.0 if stop else None if command is None else command[1])
        self.pump.run(self.cfg.sample_period_s)
        self.patient.step(self.pump.rate_ml_h)

    def _finish(self, n: int) -> None:
        """After the last tick: the final pump status and FINISHED, then linger for the runtime's."""
        self._pump_status(n)
        self._heartbeat(n, self.d.PRESSOR_STATE_FINISHED)
        self._flush()
        until = time.monotonic() + 2.0
        finished = self.d.PRESSOR_STATE_FINISHED
        while time.monotonic() < until and finished not in self.log.runtime_states:
            for m in self._receive(0.1):
                self._handle(m)

    def _lockstep(self) -> None:
        cfg = self.cfg
        for k in range(cfg.n_ticks):
            self._measure(k)
            last_heard = time.monotonic()
            while k not in self.log.commands:
                if time.monotonic() - last_heard > cfg.link_timeout_s:
                    raise LinkDown(f"no command for tick {k}")
                self._tick_frames(k)
                self._flush()
                resend_at = time.monotonic() + cfg.retransmit_s
                while k not in self.log.commands and time.monotonic() < resend_at:
                    for m in self._receive(resend_at - time.monotonic()):
                        self._handle(m)
                if k not in self.log.commands:
                    self.log.resends += 1
            self._advance(self.pending)
            self.pending = None

    def _realtime(self) -> None:
        cfg, t0 = self.cfg, self.t_start
        for k in range(cfg.n_ticks):
            self._tick_frames(k, with_sample=self._measure(k))
            self._flush()
            release = t0 + (k + 1) * cfg.sample_period_s
            while (wait := release - time.monotonic()) > 0:
                for m in self._receive(wait):
                    self._handle(m)
            self.log.missed_commands += k not in self.log.commands
            self._advance(self.pending)  # the newest command, late or not
            self.pending = None

    def run(self) -> DeviceLog:
        """Handshake, play every tick, finish; ``log.outcome`` is "finished" or why it stopped."""
        try:
            self.handshake()
            self._realtime() if self.cfg.realtime else self._lockstep()
            self._finish(self.cfg.n_ticks)
            self.log.outcome = "finished"
        except LinkDown as exc:
            # Real time: the runtime may end the run (FINISHED) and close before the final status.
            over = self.d.PRESSOR_STATE_FINISHED in self.log.runtime_states
            self.log.outcome = "finished" if over else str(exc)
        return self.log
