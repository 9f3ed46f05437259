"""Defence in depth: the device's pump enforces its own limits and watchdog, whatever the runtime does.

A rogue runtime end, scripted in the test, talks to a real ``pressor device`` process over a pty.
"""

from __future__ import annotations

import math
import subprocess
from pathlib import Path

from pressor.contracts.faults import PUMP_ALARM_OUT_OF_RANGE, PUMP_ALARM_WATCHDOG
from pressor.link import Hello, PtyPair, RuntimeSession
from tests.support.sil_helpers import ROOT, poll_until_exit, spawn_device

MAX_RATE_ML_H = 120.0


def _scenario(tmp_path: Path, watchdog_s: float) -> Path:
    text = (ROOT / "hil_sim" / "scenarios" / "paper-tracking.toml").read_text()
    text = text.replace("[pump]\n", f"[pump]\nwatchdog_s = {watchdog_s}\nsafe_rate_ml_h = 0.0\n")
    path = tmp_path / "defence.toml"
    path.write_text(text)
    return path


def _start(*args: str) -> tuple[subprocess.Popen, PtyPair, RuntimeSession, list]:
    pair = PtyPair.open()
    ep = RuntimeSession(pair.leader_port())
    statuses: list = []
    ep.on_message = lambda m: statuses.append(m) if m.get_type() == "PUMP_STATUS" else None
    proc = spawn_device(pair, *args)
    ep.handshake(Hello("rogue"), timeout_s=30.0)
    return proc, pair, ep, statuses


def _drain(proc: subprocess.Popen, pair: PtyPair, ep: RuntimeSession) -> None:
    poll_until_exit(proc, ep, timeout_s=10.0)
    proc.wait(timeout=30)
    pair.close_follower()
    ep.close()


def test_pump_clamps_out_of_range_and_non_finite_commands_from_a_rogue_runtime(tmp_path):
    rogue = [500.0, -10.0, math.inf, math.nan, 1e30, 60.0]
    scenario = _scenario(tmp_path, watchdog_s=5.0)
    proc, pair, ep, statuses = _start(
        "--scenario", str(scenario), "--duration", str(0.1 * len(rogue))
    )
    for rate in rogue:
        sample = ep.wait_for_sample(5.0)
        assert sample is not None
        ep.send_command(sample.tick, rate)
    _drain(proc, pair, ep)
    assert statuses, "the device reported no pump status"
    for status in statuses:
        assert math.isfinite(status.delivered_ml_h)
        assert 0.0 <= status.delivered_ml_h <= MAX_RATE_ML_H
    assert any(s.alarms & PUMP_ALARM_OUT_OF_RANGE for s in statuses)


def test_pump_watchdog_falls_back_to_safe_rate_when_the_runtime_goes_silent(tmp_path):
    scenario = _scenario(tmp_path, watchdog_s=0.5)
    proc, pair, ep, statuses = _start(
        "--scenario", str(scenario), "--duration", "1.5", "--realtime"
    )
    ticks = 0
    while ticks < 15:
        sample = ep.wait_for_sample(2.0)
        assert sample is not None
        ticks += 1
        if sample.tick < 3:  # then silence: no command for the rest of the run
            ep.send_command(sample.tick, 40.0)
    _drain(proc, pair, ep)
    late = [s for s in statuses if s.tick >= 10]  # 0.7 s after the last command > 0.5 s watchdog
    assert late, "no pump status after the watchdog period"
    assert all(s.alarms & PUMP_ALARM_WATCHDOG for s in late)
    assert all(s.delivered_ml_h == 0.0 for s in late)
    early = [s for s in statuses if s.tick < 3]
    assert early and all(not s.alarms & PUMP_ALARM_WATCHDOG for s in early)
