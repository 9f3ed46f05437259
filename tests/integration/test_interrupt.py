"""SIGINT / SIGTERM stop ``pressor sil``, ``run`` and ``device`` gracefully: real subprocesses, real
signals; the recording, telemetry log and summary hold the run up to the stop."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from pressor.link import (
    LINK_REALTIME,
    DeviceSession,
    ManualClock,
    PtyPair,
    RuntimeSession,
    Signing,
    read_tlog,
)
from pressor.link.dialect import pressor as mavlink
from tests.support.sil_helpers import ROOT, poll_until_exit, rrd_columns, spawn_device

ENV = dict(os.environ, CI="1", PYTHONPATH=str(ROOT))


def _start(*args: str, cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "pressor", *args],
        cwd=cwd,
        env=ENV,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait_for(pred, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not pred():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


def _frames(path: Path) -> list:
    mav = mavlink.MAVLink(None)
    return [mav.decode(bytearray(frame)) for _, frame in read_tlog(path)]


def _assert_one_line(stderr: str, prog: str, sig: signal.Signals) -> None:
    assert "Traceback" not in stderr
    start = f"{prog}: warning: --controller"  # the run's start says a baseline is not cautious
    lines = [ln for ln in stderr.splitlines() if ln.strip() and not ln.startswith(start)]
    assert len(lines) == 1 and lines[0].startswith(f"{prog}: interrupted by {sig.name}"), stderr


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_stops_sil_keeping_recording_tlog_and_summary(tmp_path, sig):
    rrd, tlog, summary = tmp_path / "run.rrd", tmp_path / "run.tlog", tmp_path / "s.json"
    proc = _start(
        "sil", "--controller", "pi", "--realtime", "--duration", "120", "--rrd", str(rrd),
        "--tlog", str(tlog), "--summary", str(summary), cwd=tmp_path,
    )  # fmt: skip
    try:
        # the recording's hidden temporary file appears once the run started
        _wait_for(lambda: any(p.name.startswith(".run.rrd") for p in tmp_path.iterdir()), 60)
        time.sleep(1.5)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 128 + sig
    _assert_one_line(err, "pressor sil", sig)
    data = json.loads(summary.read_text())
    assert data["interrupted"] is True and data["ended"] == f"interrupted by {sig.name}"
    assert 5 <= data["ticks"] < 1200
    recorded = rrd_columns(rrd)["/pump/command_ml_h"]  # real time: device ticks, a few skipped
    assert len(recorded) >= data["ticks"] - 3
    commands = [f for f in _frames(tlog) if f.get_type() == "INFUSION_COMMAND"]
    assert commands[-2].tick == max(recorded)  # the recording holds the run up to the stop
    assert commands[-1].tick == max(recorded) + 1  # then the safe rate for the next tick
    assert commands[-1].mode == mavlink.PRESSOR_COMMAND_MODE_SAFE
    assert commands[-1].rate_ml_h == pytest.approx(commands[-2].rate_ml_h, abs=1e-3)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporaries left


def _exit_s_after_signal(proc: subprocess.Popen, sig: signal.Signals) -> tuple[float, str]:
    """Send ``sig`` to ``proc``; the wall seconds until it exited, and its stderr."""
    t0 = time.monotonic()
    proc.send_signal(sig)
    proc.wait(timeout=30)
    elapsed = time.monotonic() - t0
    return elapsed, proc.stderr.read()


def test_ctrl_c_ends_a_lockstep_sil_within_1_s_with_one_line_and_the_true_map_recorded(tmp_path):
    rrd, summary = tmp_path / "run.rrd", tmp_path / "s.json"
    proc = _start(
        "sil", "--controller", "pi", "--duration", "3600", "--rrd", str(rrd),
        "--summary", str(summary), cwd=tmp_path,
    )  # fmt: skip
    try:
        _wait_for(lambda: any(p.name.startswith(".run.rrd") for p in tmp_path.iterdir()), 60)
        time.sleep(1.0)  # mid-run: an hour in lockstep takes several seconds
        elapsed_s, err = _exit_s_after_signal(proc, signal.SIGINT)
    finally:
        proc.kill()
    assert proc.returncode == 130
    _assert_one_line(err, "pressor sil", signal.SIGINT)  # no "device exited with ..."
    assert elapsed_s <= 1.0, f"exit {elapsed_s:.2f} s after SIGINT"
    ticks = json.loads(summary.read_text())["ticks"]
    assert 10 <= ticks < 36000
    columns = rrd_columns(rrd)
    assert len(columns["/patient/map_mmhg"]) == ticks
    true_map = columns["/patient/map_true_mmhg"]  # the device's truth up to the stop
    assert set(range(ticks)) <= set(true_map) and all(30 < v < 200 for v in true_map.values())


@pytest.mark.parametrize("delay_s", [0.3, 0.6, 1.0])
def test_ctrl_c_while_sil_starts_ends_it_within_1_s_with_one_line(tmp_path, delay_s):
    proc = _start("sil", "--controller", "pi", "--rrd", str(tmp_path / "run.rrd"), cwd=tmp_path)
    try:
        time.sleep(delay_s)  # still loading: its imports, the scenario, the controller
        elapsed_s, err = _exit_s_after_signal(proc, signal.SIGINT)
    finally:
        proc.kill()
    assert proc.returncode == 130
    _assert_one_line(err, "pressor sil", signal.SIGINT)
    assert elapsed_s <= 1.0, f"exit {elapsed_s:.2f} s after SIGINT"
    # nothing half-written: still loading, nothing at all; on a fast host the run may have begun by
    # 1 s, and then its recording is finished and readable (the ticks before the stop, perhaps
    # none), never a temp file
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left in ([], ["run.rrd"]), left
    if left:  # readable to its end, the MAP recorded at every tick up to the stop
        ticks = sorted(rrd_columns(tmp_path / "run.rrd").get("/patient/map_mmhg", {}))
        assert ticks == list(range(len(ticks)))


def _device_thread(pair: PtyPair, stop: threading.Event, key: Path) -> threading.Thread:
    """A simulated device (the project's world) driving the runtime from this process."""
    from pressor.hil_sim.devices.device import run_device
    from pressor.hil_sim.world import World

    def run() -> None:
        clock = ManualClock()
        ep = DeviceSession(pair.leader_port(), clock=clock, signing=Signing.from_file(key))
        try:
            run_device(ep, World("paper-tracking", 3, 0.1), clock, duration_s=120, realtime=True)
        except Exception:
            pass
        finally:
            stop.set()
            ep.close()

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def test_sigint_stops_pressor_run_with_safe_command_and_summary(tmp_path):
    pair = PtyPair.open()
    rrd, summary = tmp_path / "run.rrd", tmp_path / "s.json"
    key = Signing.generate().write(tmp_path / "key")
    proc = _start(
        "run", "--port", pair.follower_path, "--controller", "pi", "--realtime",
        "--signing-key", str(key), "--confirm-above-soft-limit",  # no dose line beside the stop's
        "--rrd", str(rrd), "--summary", str(summary), cwd=tmp_path,
    )  # fmt: skip
    done = threading.Event()
    _device_thread(pair, done, key)
    try:
        _wait_for(lambda: any(p.name.startswith(".run.rrd") for p in tmp_path.iterdir()), 60)
        time.sleep(1.5)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
        pair.close()
    assert proc.returncode == 130
    _assert_one_line(err, "pressor run", signal.SIGINT)
    data = json.loads(summary.read_text())
    assert data["interrupted"] is True and data["ticks"] >= 5
    assert len(rrd_columns(rrd)["/pump/command_ml_h"]) >= data["ticks"] - 3


def test_sigterm_stops_pressor_device_with_finished_heartbeat_and_valid_tlog(tmp_path):
    pair = PtyPair.open()
    tlog, key = tmp_path / "dev.tlog", Signing.generate().write(tmp_path / "key")
    proc = spawn_device(
        pair, "--realtime", "--duration", "120", "--patient-seed", "4", "--tlog", str(tlog),
        "--signing-key", str(key),
    )  # fmt: skip
    ep = RuntimeSession(pair.leader_port(), clock=time.monotonic, signing=Signing.from_file(key))
    from pressor.link import Hello

    try:
        peer = ep.handshake(Hello("pi", link_mode=LINK_REALTIME), timeout_s=30)
        pair.close_follower()
        answered = 0
        while answered < 20:
            x = ep.wait_for_sample(2.0)
            assert x is not None
            ep.send_command(x.tick, 1.0)
            answered += 1
        proc.send_signal(signal.SIGTERM)
        poll_until_exit(proc, ep, 15)
        proc.wait(timeout=15)
    finally:
        proc.kill()
        pair.close()
    assert peer.n_ticks == 1200
    assert proc.returncode == 143
    _assert_one_line(proc.stderr.read(), "pressor device", signal.SIGTERM)
    assert ep.peer_heartbeat is not None
    assert ep.peer_heartbeat.state == mavlink.PRESSOR_STATE_FINISHED
    frames = _frames(tlog)
    assert frames[-1].get_type() == "PRESSOR_HEARTBEAT"
    assert frames[-1].state == mavlink.PRESSOR_STATE_FINISHED
    assert 20 <= frames[-1].tick < 1200
