"""The loop over a real link: lockstep handshake and ticks over a pty, supervisor in the loop.

The device side here is a small first-order plant driven by a ``DeviceSession`` in a
thread (the real device process is exercised by tests/integration/test_sil.py).
"""

from __future__ import annotations

import math
import os
import threading

import numpy as np

os.environ.setdefault("CI", "1")

from pressor.baselines.pi import PIController  # noqa: E402
from pressor.link import (  # noqa: E402
    LINK_LOCKSTEP,
    STATE_FINISHED,
    DeviceSession,
    Hello,
    LinkClosedError,
    PtyPair,  # noqa: E402
    RuntimeSession,
    Signing,
)
from pressor.runtime.core.supervisor import Supervisor  # noqa: E402
from pressor.runtime.core.supervisor_config import State, supervisor_config_for  # noqa: E402
from pressor.runtime.shell.loop import DeviceStalled, Loop  # noqa: E402
from tests.support.link_doubles import loop_pair, tick_inputs  # noqa: E402

TS = 0.1


def f32(x: float) -> float:
    return float(np.float32(x))


def plant_device(port, n_ticks, nan_ticks=(), signing=None, stall_at=None, log=None):
    """Lockstep device: MAP' = (-(MAP-60) + 0.5·u)/30, target 80; sends tick k, waits for command k."""
    ep = DeviceSession(port, signing=signing)
    ep.handshake(Hello("test-plant", 7, TS, 0.0, n_ticks, LINK_LOCKSTEP))
    x = 60.0
    for k in range(n_ticks):
        if stall_at is not None and k == stall_at:
            return
        ep.clock.t = k * TS
        meas = math.nan if k in nan_ticks else x
        ep.send_tick(tick_inputs(k, k * TS, f32(meas), 0, 80.0, 0.55, 150.0, 40.0, True))
        cmd = ep.wait_for_command(k, 5.0)
        assert cmd is not None, f"no command for tick {k}"
        if log is not None:
            log.append((k, f32(meas), cmd.rate_ml_h))
        x = x + TS * (-(x - 60.0) + 0.5 * cmd.rate_ml_h) / 30.0
    try:
        ep.send_heartbeat(n_ticks - 1, STATE_FINISHED)
    except LinkClosedError:  # the runtime may already have closed after the last command
        pass


def reference(n_ticks, nan_ticks=()):
    """The same closed loop in-process: observe -> PI step -> apply -> advance."""
    pi = PIController(sample_period_s=TS)
    x, out = 60.0, []
    for k in range(n_ticks):
        meas = math.nan if k in nan_ticks else f32(x)
        u = f32(pi.step(meas, 80.0, 0.55, 150.0, 40.0))
        out.append((k, meas, u))
        x = x + TS * (-(x - 60.0) + 0.5 * u) / 30.0
    return out


def run_runtime(port, signing=None, stall_timeout_s=10.0, device=None, **sup_overrides):
    """Run the loop; with ``device`` (its thread) wait for it before closing the port, so a
    closing leader never discards the last command before the device has read it."""
    ep = RuntimeSession(port, signing=signing)
    peer = ep.handshake(Hello("pi", link_mode=LINK_LOCKSTEP), timeout_s=10.0)
    pi = PIController(sample_period_s=peer.sample_period_s)
    sup = Supervisor(supervisor_config_for(pi, peer.sensor_noise_mmhg, **sup_overrides))
    loop = Loop(pi, sup, ep)
    try:
        return peer, loop.run_lockstep(peer.n_ticks, stall_timeout_s=stall_timeout_s)
    finally:
        if device is not None:
            device.join(10)
        ep.close()


def with_pty_device(n_ticks, **device_kw):
    pair = PtyPair.open()
    log: list = []
    port = pair.follower_port()  # opened by path with pyserial, as a device process does
    pair.close_follower()

    def device():
        try:
            plant_device(port, n_ticks, log=log, **device_kw)
        finally:
            port.close()

    th = threading.Thread(target=device, daemon=True)
    th.start()
    return pair, th, log


def test_lockstep_over_pty_reproduces_in_process_loop_sample_for_sample():
    n = 300
    pair, th, device_log = with_pty_device(n)
    port = pair.leader_port()
    peer, res = run_runtime(port, device=th)
    assert peer.name == "test-plant" and peer.patient_seed == 7 and peer.n_ticks == n
    assert res.ended == "completed"
    assert list(res.trajectory["tick"]) == list(range(n))
    ref = reference(n)
    assert device_log == ref  # the device saw exactly the in-process commands
    assert res.ticks_in_state["AUTO"] == n
    assert res.commands_out_of_range == 0
    assert res.link["bad_crc"] == 0 and res.link["seq_gaps"] == 0


def test_nan_samples_in_loop_hold_command_then_recover_bumplessly():
    n = 200
    nan_ticks = set(range(50, 60))
    a, b = loop_pair()
    log: list = []
    th = threading.Thread(
        target=plant_device, args=(b, n), kwargs={"nan_ticks": nan_ticks, "log": log}, daemon=True
    )
    th.start()
    _, res = run_runtime(a, recover_after_s=2.0, reentry_step_ml_h=0.5)
    th.join(10)
    cmds = res.trajectory["command_ml_h"]
    states = res.trajectory["state"]
    assert all(states[50:60] == State.HOLD)
    assert np.all(cmds[50:60] == cmds[49])
    assert State.RECOVERING in set(states[60:])
    assert np.max(np.abs(np.diff(cmds[50:]))) <= 3.0 * 20.0  # no unbounded jump anywhere
    reentry = np.flatnonzero(states == State.RECOVERING)
    assert np.max(np.abs(np.diff(cmds[reentry[0] - 1 : reentry[-1] + 2]))) <= 0.5 + 1e-6
    assert res.detections["MAP_NAN"] == 1
    assert [t["to"] for t in res.transitions] == ["AUTO", "HOLD", "RECOVERING", "AUTO"]
    assert res.transitions[1]["tick"] == 50 and res.transitions[1]["faults"] == ["MAP_NAN"]


def test_signed_link_runs_and_counts_no_refusals():
    sig = Signing.generate(seed=1)
    a, b = loop_pair()
    th = threading.Thread(target=plant_device, args=(b, 50), kwargs={"signing": sig}, daemon=True)
    th.start()
    _, res = run_runtime(a, signing=sig)
    th.join(10)
    assert res.ended == "completed" and len(res.trajectory["tick"]) == 50
    assert res.link["refused_unsigned"] == 0 and res.link["refused_bad_signature"] == 0


def test_stalled_device_ends_lockstep_run_with_device_stalled():
    a, b = loop_pair()
    th = threading.Thread(target=plant_device, args=(b, 100), kwargs={"stall_at": 20}, daemon=True)
    th.start()
    _, res = run_runtime(a, stall_timeout_s=1.0)  # the loop sent the safe command, then ended
    th.join(10)
    assert isinstance(res.error, DeviceStalled) and "after 20 ticks" in str(res.error)
    assert res.ended.startswith("failed: device sent no sample")
    assert len(res.trajectory["tick"]) == 20


def realtime_device(port, n_send, stop):
    """Real-time device on the wall clock: a sample every 0.1 s for ``n_send`` ticks, then silence."""
    import time

    ep = DeviceSession(port)
    ep.handshake(Hello("rt-plant", 1, TS, 0.0, 0, LINK_LOCKSTEP))
    t0 = time.perf_counter()
    for k in range(n_send):
        ep.send_tick(tick_inputs(k, k * TS, 70.0, 0, 80.0, 0.55, 150.0, 40.0, True))
        while time.perf_counter() < t0 + (k + 1) * TS:
            ep.poll(0.01)
    while not stop.is_set():  # keep the port open but send nothing: a silent, not a closed, link
        ep.poll(0.05)


def test_realtime_watchdogs_flag_stale_sample_then_link_loss_and_failsafe():
    a, b = loop_pair()
    stop = threading.Event()
    th = threading.Thread(target=realtime_device, args=(b, 10, stop), daemon=True)
    th.start()
    ep = RuntimeSession(a)
    ep.handshake(Hello("pi"), timeout_s=10.0)
    pi = PIController(sample_period_s=TS)
    # a sample age limit of 0.35 s (--sample-age-limit-s 0.35): stale before the link is lost
    sup = Supervisor(supervisor_config_for(pi, 0.0, safe_rate_ml_h=0.0, stale_after_s=0.35))
    try:
        res = Loop(pi, sup, ep).run_realtime(n_ticks=25)
    finally:
        stop.set()
        th.join(5)
        ep.close()
    states = list(res.trajectory["state"])
    to = [t["to"] for t in res.transitions]
    assert to[:3] == ["AUTO", "HOLD", "FAILSAFE"], res.transitions
    assert res.transitions[1]["faults"] == ["STALE_SAMPLE"]
    assert "LINK_LOSS" in res.transitions[2]["faults"]
    hold_at, failsafe_at = states.index(State.HOLD), states.index(State.FAILSAFE)
    # samples stop after ~1.0 s: stale after 0.35 s, link loss after 1.0 s (a few ticks of slack)
    assert 10 <= hold_at <= 16 and 6 <= failsafe_at - hold_at <= 9
    assert res.timing["ticks"] == 25
    assert all(0.0 <= c <= 120.0 for c in res.trajectory["command_ml_h"])


def test_supervisor_config_reads_design_envelope_from_generated_module_constants(tmp_path):
    from pressor.contracts.module_hash import MODULE_SHA_PREFIX, module_text_sha256
    from pressor.runtime.inputs.controller_loader import load_generated_module

    src = tmp_path / "fake_gen.py"
    text = (
        "GRID_LO = (0.25, 100.0, 10.0)\n"
        "GRID_HI = (1.0, 200.0, 45.0)\n"
        "RATE_BOUNDS = (2e-4, 0.06, 0.1)\n"
        "class Controller:\n"
        "    sample_period_s = 0.1\n"
        "    max_rate_ml_h = 120.0\n"
        f"{MODULE_SHA_PREFIX}''\n"
    )
    # the loader refuses modules without an intact self-hash (codegen's integrity line)
    src.write_text(
        text.replace(f"{MODULE_SHA_PREFIX}''", f"{MODULE_SHA_PREFIX}'{module_text_sha256(text)}'")
    )
    ctrl = load_generated_module(src).Controller()
    cfg = supervisor_config_for(ctrl, sensor_noise_mmhg=2.0)
    assert cfg.sched_box == ((0.25, 1.0), (100.0, 200.0), (10.0, 45.0))
    assert cfg.sched_rate_bounds == (2e-4, 0.06, 0.1)
    assert cfg.sched_required and cfg.sensor_noise_mmhg == 2.0 and cfg.sched_action == "advise"
    pi_cfg = supervisor_config_for(PIController(), sensor_noise_mmhg=0.0)
    assert pi_cfg.sched_box is None and not pi_cfg.sched_required
    assert pi_cfg.sensor_noise_mmhg == 0.0  # a noise-free monitor: the flatline rules are off
