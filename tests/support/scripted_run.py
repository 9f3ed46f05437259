"""``pressor run`` as a real process against a scripted lockstep device on bridged ttys.

The device (:class:`link.DeviceSession`, signed with the same key file) sends a known MAP per tick,
so a test knows exactly between which ticks a target file or a stdin line changes (the
clinician-input tests and the controller-fault run share it).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

from rerun.chunk import RrdReader

from pressor.link import (
    LINK_LOCKSTEP,
    STATE_FINISHED,
    DeviceSession,
    Hello,
    ManualClock,
    PumpStatus,
    Signing,
    open_port,
)
from pressor.link.dialect import pressor as mavlink
from pressor.runtime.record.blueprint import EVENTS_ENTITY
from tests.support.link_doubles import tick_inputs
from tests.support.sil_helpers import ROOT, bridged_ttys

TS = 0.1
DEVICE_TARGET = 80.0  # mmHg: what the scripted device's MAP_TARGET says
SYRINGE = {"drug": "phenylephrine", "concentration_ug_ml": 100.0, "pump_max_ml_h": 120.0}


def start_run(port: str, key: Path, tmp_path: Path, *args: str) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "pressor", "run", "--port", port, "--signing-key", str(key)]
    cmd += ["--controller", "pi", *args]
    return subprocess.Popen(
        cmd,
        cwd=tmp_path,
        env=dict(os.environ, CI="1", PYTHONPATH=str(ROOT)),
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def scripted_device(
    port: str,
    key: Path,
    n: int,
    *,
    syringe: dict | None = None,
    send_target: bool = True,
    before_tick: Callable[[int], object] | None = None,
    map_at: Callable[[int], float] = lambda k: 60.0 + 0.05 * k,
) -> DeviceSession:
    """A lockstep device: hello (with ``syringe``), then ``n`` ticks of MAP ``map_at(k)`` (60 mmHg
    rising), each with its scheduling parameters and (if ``send_target``) a MAP_TARGET of 80 mmHg;
    waits for every command, reports the pump, finishes. ``before_tick(k)`` runs before tick k is
    sent."""
    ep = DeviceSession(open_port(port), signing=Signing.from_file(key), clock=ManualClock())
    hello = Hello("scripted", 0, TS, 0.0, n, LINK_LOCKSTEP, **(syringe or SYRINGE))
    ep.handshake(hello, timeout_s=60.0)
    if n == 0:
        return ep
    for k in range(n):
        if before_tick is not None:
            before_tick(k)
        ep.clock.t = k * TS
        x = tick_inputs(k, k * TS, map_at(k), target_mmhg=DEVICE_TARGET)
        if send_target:
            ep.send_tick(x)
        else:  # scheduling parameters and the sample, no MAP_TARGET at all
            ep.send_fields(mavlink.MAVLINK_MSG_ID_SCHEDULING_PARAMS, k, x.K, x.T_s, x.tau_s, 1)
            ep.send_fields(mavlink.MAVLINK_MSG_ID_MAP_SAMPLE, x.sim_time_s, k, x.map_mmhg, 0)
        cmd = ep.wait_for_command(k, 15.0)
        assert cmd is not None, f"no command for tick {k}"
        ep.send_pump_status(PumpStatus(k + 1, cmd.rate_ml_h, 0.0, 0), flush=False)
    ep.send_heartbeat(n, STATE_FINISHED)
    return ep


def new_key(tmp_path: Path) -> Path:
    key = tmp_path / "link.key"
    Signing.generate().write(key)
    return key


def recorded_events(rrd: Path) -> list[tuple[int, str]]:
    """Every (tick, text) of the recording's event log."""
    out = []
    for chunk in RrdReader(str(rrd)).stream().to_chunks():
        batch = chunk.to_record_batch()
        if str(chunk.entity_path) != EVENTS_ENTITY or "TextLog:text" not in batch.schema.names:
            continue
        texts = [v[0] for v in batch.column("TextLog:text").to_pylist()]
        out += zip(batch.column("tick").to_pylist(), texts, strict=True)
    return sorted(out)


def run_against_device(
    tmp_path: Path,
    run_args: list[str],
    n: int,
    before_tick: Callable[[int, subprocess.Popen], object] | None = None,
    **device_kw,
) -> tuple:
    """``pressor run RUN_ARGS`` against the scripted device; (exit code, stdout + stderr, summary,
    rrd).

    ``before_tick(k, run)`` runs before the device sends tick k (``run``: the runtime process).
    """
    key = new_key(tmp_path)
    summary, rrd = tmp_path / "s.json", tmp_path / "run.rrd"
    with bridged_ttys() as (device_port, runtime_port):
        run = start_run(
            runtime_port, key, tmp_path, "--summary", str(summary), "--rrd", str(rrd), *run_args
        )
        before = None if before_tick is None else lambda k: before_tick(k, run)
        try:
            scripted_device(device_port, key, n, before_tick=before, **device_kw).close()
            out, err = run.communicate(timeout=120)
        finally:
            run.kill()
    return run.returncode, out + err, json.loads(summary.read_text()), rrd
