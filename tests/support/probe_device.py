"""A probing device for ``pressor run``: a real lockstep device over bridged ttys that sends
good ticks and, where a test says so, the bad frame under test (a backwards time, a tick jump, a
mid-run hello, an echo of the runtime's own frames, ...).

It is the project's :class:`link.DeviceSession` (real, signed MAVLink 2 frames on a real pty),
driven by hand: :meth:`Probe.tick` sends one tick's frames, :meth:`Probe.command` waits for its
answer, :meth:`Probe.raw` sends any frame. The runtime is the real ``pressor run`` process
(:func:`tests.support.scripted_run.start_run`), so what it does on a bad input is what a bedside
box would do.
"""

from __future__ import annotations

import json
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pressor.link import (
    LINK_LOCKSTEP,
    LINK_REALTIME,
    STATE_FINISHED,
    Command,
    DeviceSession,
    Hello,
    LinkClosedError,
    ManualClock,
    PeerRefused,
    PumpStatus,
    Signing,
    open_port,
)
from pressor.link.dialect import pressor as mavlink
from tests.support.scripted_run import SYRINGE, TS, new_key, start_run
from tests.support.sil_helpers import bridged_ttys

ID_SAMPLE = mavlink.MAVLINK_MSG_ID_MAP_SAMPLE
ID_SCHED = mavlink.MAVLINK_MSG_ID_SCHEDULING_PARAMS
ID_TARGET = mavlink.MAVLINK_MSG_ID_MAP_TARGET
ID_STATUS = mavlink.MAVLINK_MSG_ID_PUMP_STATUS


@dataclass
class Probe:
    """A lockstep device end, handshake done; ``commands`` maps each tick to its command."""

    ep: DeviceSession
    ts: float = TS
    commands: dict[int, Command] = field(default_factory=dict)
    refusals: list[tuple[int, str]] = field(default_factory=list)

    def tick(
        self,
        k: int,
        map_mmhg: float = 65.0,
        *,
        sim_time_s: float | None = None,
        target_mmhg: float = 80.0,
        status: tuple[float, int] | None = None,
    ) -> None:
        """Send tick ``k``: its pump status (``status`` = (delivered ml/h, alarms), default the
        last command's rate, none at tick 0), scheduling parameters, target and MAP sample (time
        ``sim_time_s``, default ``k`` periods)."""
        ep = self.ep
        t = k * self.ts if sim_time_s is None else sim_time_s
        ep.clock.t = k * self.ts
        if k > 0:
            last = self.commands.get(k - 1)
            rate, alarms = (last.rate_ml_h if last else 0.0, 0) if status is None else status
            ep.send_pump_status(PumpStatus(k, rate, 0.0, alarms), flush=False)
        ep.send_fields(ID_SCHED, k, 0.5, 150.0, 30.0, 1, flush=False)
        ep.send_fields(ID_TARGET, k, target_mmhg, flush=False)
        ep.send_fields(ID_SAMPLE, t, k, map_mmhg, 0)

    def command(self, k: int, timeout_s: float = 15.0) -> Command | None:
        """The command answering tick ``k`` (``None`` after ``timeout_s`` s). A PRESSOR_REFUSAL
        of a mid-run hello is kept in ``refusals`` and the wait goes on (the probe stays to see
        what the runtime does next)."""
        end = time.monotonic() + timeout_s
        while True:
            try:
                cmd = self.ep.wait_for_command(k, max(0.0, end - time.monotonic()))
                break
            except PeerRefused as exc:
                self.refusals.append((exc.reason, exc.text))
                self.ep.peer_refusal = None
        if cmd is not None:
            self.commands[k] = cmd
        return cmd

    def run(self, ticks: range, map_mmhg: float = 65.0, **kw: Any) -> None:
        """Send each tick of ``ticks`` and wait for its answer (asserting it came)."""
        for k in ticks:
            self.tick(k, map_mmhg, **kw)
            assert self.command(k) is not None, f"no command for tick {k}"

    def raw(self, msgid: int, *fields: Any) -> None:
        """Send one frame of message ``msgid`` with ``fields`` in XML order."""
        self.ep.send_fields(msgid, *fields)

    def finish(self, k: int) -> None:
        """The final pump status and FINISHED after the last tick ``k - 1``."""
        last = self.commands.get(k - 1)
        self.ep.send_pump_status(
            PumpStatus(k, last.rate_ml_h if last else 0.0, 0.0, 0), flush=False
        )
        self.ep.send_heartbeat(k, STATE_FINISHED)

    def drain(self, seconds: float) -> None:
        """Keep reading (commands the runtime sends by itself, its heartbeats) for ``seconds``."""
        end = time.monotonic() + seconds
        try:
            while (left := end - time.monotonic()) > 0:
                self.ep.poll(left)
        except LinkClosedError:
            pass


@dataclass
class ProbeRun:
    """A ``pressor run`` process against a :class:`Probe`; its outputs once it ended."""

    proc: subprocess.Popen
    probe: Probe
    dir: Path
    out: str = ""
    err: str = ""

    @property
    def summary(self) -> dict[str, Any]:
        return json.loads((self.dir / "s.json").read_text())

    def wait(self, timeout_s: float = 60.0) -> int:
        """Wait for the runtime to exit; keep its stdout and stderr; return its exit code."""
        self.out, self.err = self.proc.communicate(timeout=timeout_s)
        return self.proc.returncode


@contextmanager
def probe_run(
    tmp_path: Path,
    *run_args: str,
    n_ticks: int = 0,
    hello: dict[str, Any] | None = None,
    realtime: bool = False,
    period_s: float = TS,
) -> Iterator[ProbeRun]:
    """Start ``pressor run --controller pi RUN_ARGS`` (summary ``s.json``, tlog ``run.tlog`` in
    ``tmp_path``) on one end of bridged ttys and a :class:`Probe` on the other, handshake done
    with a hello announcing ``n_ticks`` (``hello`` overrides the syringe fields) and lockstep, or
    real time with ``realtime`` (then pass ``--realtime`` in ``run_args``), at ``period_s`` (then
    pass the ``--rate`` that matches)."""
    key = new_key(tmp_path)
    with bridged_ttys() as (device_port, runtime_port):
        args = ["--summary", str(tmp_path / "s.json"), "--tlog", str(tmp_path / "run.tlog")]
        proc = start_run(runtime_port, key, tmp_path, *args, *run_args)
        try:
            ep = DeviceSession(
                open_port(device_port), signing=Signing.from_file(key), clock=ManualClock()
            )
            ep.handshake(
                Hello(
                    "probe",
                    0,
                    period_s,
                    0.0,
                    n_ticks,
                    LINK_REALTIME if realtime else LINK_LOCKSTEP,
                    **{**SYRINGE, **(hello or {})},
                ),
                timeout_s=60.0,
            )
            yield ProbeRun(proc, Probe(ep, period_s), tmp_path)
        finally:
            proc.kill()
            proc.wait()
