"""``pressor device`` as a real process on a pty, driven by a scripted runtime end."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from pressor.baselines.pi import PIController
from pressor.hil_sim.devices.device import main as device_main
from pressor.hil_sim.episode import simulate
from pressor.hil_sim.world import World
from pressor.link import (
    REFUSAL_DRUG,
    STATE_FAULT,
    STATE_FINISHED,
    DeviceSession,
    Hello,
    HelloRefused,
    LinkClosedError,
    PtyPair,
    RuntimeSession,
    Signing,
    TlogWriter,
    read_tlog,
)
from tests.support.sil_helpers import poll_until_exit, spawn_device


def _run_pi_runtime(ep: RuntimeSession, max_ticks: int = 10**9) -> tuple[list, list]:
    """A minimal runtime: PI controller, one command per sample, until the device finishes."""
    peer = ep.handshake(Hello("pi"), timeout_s=30.0)
    ctrl = PIController(sample_period_s=peer.sample_period_s)
    maps, cmds = [], []
    while len(maps) < max_ticks:
        x = ep.wait_for_sample(5.0)
        if x is None:
            assert ep.peer_heartbeat is not None and ep.peer_heartbeat[1] == STATE_FINISHED
            break
        assert x.sched_tick == x.target_tick == x.tick
        u = ctrl.step(x.map_mmhg, x.target_mmhg, x.K, x.T_s, x.tau_s)
        ep.send_command(x.tick, u)
        maps.append(x.map_mmhg)
        cmds.append(u)
        if len(maps) == peer.n_ticks:
            break
    # keep listening until the device is done: the last command may need answering again
    deadline = time.monotonic() + 10.0
    while len(maps) < max_ticks and time.monotonic() < deadline:
        if ep.peer_heartbeat is not None and ep.peer_heartbeat[1] == STATE_FINISHED:
            break
        try:
            ep.poll(0.05)
        except LinkClosedError:
            break
    return maps, cmds


def _finish(proc: subprocess.Popen, pair: PtyPair, ep: RuntimeSession) -> int:
    rc = proc.wait(timeout=30)
    pair.close_follower()
    ep.close()
    return rc


def test_device_process_in_lockstep_over_a_pty_matches_the_in_process_simulation():
    seed, duration = 3, 300.0
    pair = PtyPair.open()
    ep = RuntimeSession(pair.leader_port())
    proc = spawn_device(
        pair, "--scenario", "paper-tracking", "--patient-seed", str(seed), "--duration", "300"
    )
    maps, cmds = _run_pi_runtime(ep)
    # the FINISHED heartbeat follows the last command's answer
    deadline = time.monotonic() + 10
    while ep.peer_heartbeat is None or ep.peer_heartbeat[1] != STATE_FINISHED:
        assert time.monotonic() < deadline
        try:
            ep.poll(0.1)
        except LinkClosedError:
            break
    assert _finish(proc, pair, ep) == 0, proc.stderr.read()
    assert ep.peer_hello.name == "paper-tracking" and ep.peer_hello.patient_seed == seed
    ref = simulate(World("paper-tracking", seed, 0.1), PIController(0.1), duration_s=duration)
    assert len(maps) == len(ref.map_mmhg) == 3000
    assert np.array_equal(np.array(maps), ref.map_mmhg, equal_nan=True)
    sent = np.array(cmds, dtype=np.float32).astype(float)  # float32 on the wire
    assert np.array_equal(sent, ref.command_ml_h)
    assert np.ptp(ref.map_mmhg[np.isfinite(ref.map_mmhg)]) > 1.0  # the loop really moved MAP
    c = ep.counters
    assert c.bad_crc == c.seq_gaps == c.timeouts == c.junk_bytes == 0
    assert ep.pump_status is not None and ep.pump_status.tick == 3000


def test_device_process_plays_a_named_patient_model_as_the_in_process_simulation():
    pair = PtyPair.open()
    ep = RuntimeSession(pair.leader_port())
    model = ("--patient-model", "phenylephrine-2c")
    proc = spawn_device(
        pair, "--scenario", "paper-tracking", "--patient-seed", "4", "--duration", "60", *model
    )
    maps, cmds = _run_pi_runtime(ep)
    assert _finish(proc, pair, ep) == 0, proc.stderr.read()
    world = World("paper-tracking", 4, 0.1, patient_model="phenylephrine-2c")
    ref = simulate(world, PIController(0.1), duration_s=60.0)
    assert np.array_equal(np.array(maps), ref.map_mmhg, equal_nan=True)
    assert np.array_equal(np.array(cmds, dtype=np.float32).astype(float), ref.command_ml_h)
    assert ref.map_true_mmhg[-1] > world.baseline_mmhg  # the model's drug effect arrived


def _signed_device_run(tmp_path: Path, tag: str, key: Path) -> tuple[bytes, bytes]:
    pair = PtyPair.open()
    rlog = TlogWriter(tmp_path / f"{tag}-runtime.tlog")
    ep = RuntimeSession(pair.leader_port(), signing=Signing.from_file(key), tlog=rlog)
    dlog = tmp_path / f"{tag}-device.tlog"
    proc = spawn_device(
        pair,
        *("--scenario", "paper-tracking", "--patient-seed", "5", "--duration", "20"),
        *("--signing-key", str(key), "--tlog", str(dlog)),
    )
    maps, _ = _run_pi_runtime(ep)
    assert len(maps) == 200
    assert _finish(proc, pair, ep) == 0, proc.stderr.read()
    rlog.close()
    return dlog.read_bytes(), rlog.path.read_bytes()


def test_signed_device_runs_differ_only_in_wall_clock_signatures_and_every_frame_is_signed(
    tmp_path,
):
    key = Signing.generate(seed=11).write(tmp_path / "key.hex")
    _signed_device_run(tmp_path, "a", key)
    _signed_device_run(tmp_path, "b", key)
    for end in ("device", "runtime"):
        a, b = (list(read_tlog(tmp_path / f"{t}-{end}.tlog")) for t in "ab")
        # same frames at the same run times; the signatures carry each run's wall clock
        assert [(t, f[:-13]) for t, f in a] == [(t, f[:-13]) for t, f in b]
    frames = list(read_tlog(tmp_path / "a-device.tlog"))
    assert len(frames) > 600 and all(f[2] & 1 for _, f in frames)
    stamps = [t for t, _ in frames]
    assert stamps == sorted(stamps) and stamps[-1] == 20_000_000  # run clock, µs
    signed = [int.from_bytes(f[-12:-6], "little") for _, f in frames]
    assert signed == sorted(signed) and signed[0] > 10 * 365 * 86400 * 100_000  # since 2015


def test_device_refuses_an_unsigned_runtime_at_once_naming_signing(tmp_path):
    key = Signing.generate(seed=12).write(tmp_path / "key.hex")
    pair = PtyPair.open()
    ep = RuntimeSession(pair.leader_port())  # no key: its hello and commands are unsigned
    proc = spawn_device(
        pair,
        *("--scenario", "paper-tracking", "--duration", "5", "--signing-key", str(key)),
        *("--handshake-timeout", "1.0"),
    )
    ep._hello = Hello("pi")  # answer the device's hellos (unsigned, so they are refused)
    poll_until_exit(proc, ep, timeout_s=20)
    assert _finish(proc, pair, ep) == 1
    assert ep.counters.frames_received >= 1
    assert "signing mismatch: the runtime's frames are unsigned" in proc.stderr.read()


def test_a_device_the_runtime_refuses_exits_2_with_the_runtime_s_reason():
    pair = PtyPair.open()
    ep = RuntimeSession(pair.leader_port())
    proc = spawn_device(pair, "--scenario", "paper-tracking", "--drug", "norepinephrine")
    peer = ep.handshake(Hello("pi"), timeout_s=30.0)
    line = f"device drug {peer.drug} differs from the loaded design's phenylephrine"
    ep.refuse(HelloRefused(REFUSAL_DRUG, line))
    assert proc.wait(timeout=30) == 2
    pair.close_follower()
    ep.close()
    last = proc.stderr.read().strip().splitlines()[-1]  # after the unsigned-link warning
    assert last == f"pressor device: refused by the runtime: {line}"


def test_device_retransmits_a_tick_without_answer_then_reports_fault():
    pair = PtyPair.open()
    ep = RuntimeSession(pair.leader_port())
    proc = spawn_device(
        pair,
        *("--scenario", "paper-tracking", "--duration", "5"),
        *("--retransmit", "0.05", "--link-timeout", "0.3"),
    )
    ep.handshake(Hello("pi"), timeout_s=30.0)
    first = ep.wait_for_sample(5.0)
    assert first is not None and first.tick == 0
    poll_until_exit(proc, ep, timeout_s=10)
    assert _finish(proc, pair, ep) == 1
    assert ep.counters.duplicates >= 4  # tick 0 sent again every 50 ms
    assert ep.next_sample() is None  # the loop never sees a retransmitted tick twice
    assert ep.peer_heartbeat is not None and ep.peer_heartbeat[1] == STATE_FAULT


def test_device_exits_cleanly_when_the_runtime_closes_the_link():
    pair = PtyPair.open()
    ep = RuntimeSession(pair.leader_port())
    proc = spawn_device(pair, "--scenario", "paper-tracking", "--duration", "100")
    maps, _ = _run_pi_runtime(ep, max_ticks=10)
    assert len(maps) == 10
    pair.close_follower()
    ep.close()
    assert proc.wait(timeout=30) == 0
    assert "runtime closed the link" in proc.stderr.read()


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--scenario", "no-such-scenario"], "no-such-scenario"),
        (["--rate", "0"], "--rate"),
        (["--rate", "7"], "--rate"),  # 1/7 s is not a multiple of the patient step
        (["--duration", "-1"], "--duration"),
        (["--patient-seed", "-3"], "--patient-seed"),
        (["--signing-key", "/nonexistent/key"], "--signing-key"),
    ],
)
def test_bad_device_input_exits_2_with_one_line_naming_the_option(args, needle, capsys):
    rc = device_main("device", ["--port", "loop://", *args])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and needle in err and len(err.splitlines()) == 1


def test_an_unopenable_port_exits_2(tmp_path, capsys):
    # unsigned: the key is checked before the port (tests/integration/test_key_files.py)
    rc = device_main("device", ["--port", str(tmp_path / "missing-tty"), "--no-signing"])
    assert rc == 2 and "--port" in capsys.readouterr().err


def test_realtime_device_paces_ticks_on_the_wall_clock_and_holds_the_rate_without_commands():
    pair = PtyPair.open()
    ep = RuntimeSession(pair.leader_port())
    statuses: list = []
    ep.on_message = lambda m: statuses.append(m) if m.get_type() == "PUMP_STATUS" else None
    proc = spawn_device(pair, "--scenario", "paper-tracking", "--duration", "1.0", "--realtime")
    peer = ep.handshake(Hello("pi"), timeout_s=30.0)
    assert peer.link_mode == 1 and peer.n_ticks == 10
    arrivals = []
    while len(arrivals) < 10:
        x = ep.wait_for_sample(2.0)
        assert x is not None
        arrivals.append((x.tick, time.monotonic()))
        if x.tick < 5:  # then the runtime falls silent
            ep.send_command(x.tick, 30.0)
    assert _finish(proc, pair, ep) == 0
    assert [k for k, _ in arrivals] == list(range(10))
    assert arrivals[-1][1] - arrivals[0][1] >= 0.8  # 9 periods of 0.1 s, not as fast as possible
    held = [s.delivered_ml_h for s in statuses if s.tick >= 7]
    assert held and all(r == pytest.approx(30.0, rel=0.05) for r in held)


def test_lockstep_over_a_corrupting_link_recovers_and_keeps_the_simulated_trajectory():
    import threading

    from pressor.hil_sim.devices.device import run_device
    from pressor.link import ManualClock
    from tests.support.link_doubles import FaultyPort, loop_pair

    seed, duration = 4, 30.0
    a, b = loop_pair()
    dev_port = FaultyPort(a, corrupt_every=7, seed=1)  # bursts of 3-5 frames per write
    rt_port = FaultyPort(b, corrupt_every=11, seed=2)  # one command per write
    clock = ManualClock()
    dev = DeviceSession(dev_port, clock=clock, signing=Signing.generate(seed=9))
    rt = RuntimeSession(rt_port, signing=Signing.generate(seed=9))
    out: dict = {}

    def device() -> None:
        world = World("paper-tracking", seed, 0.1)
        out["result"] = run_device(
            dev, world, clock, duration_s=duration, retransmit_s=0.02, link_timeout_s=5.0
        )

    t = threading.Thread(target=device)
    t.start()
    maps, cmds = _run_pi_runtime(rt)
    t.join()
    assert out["result"].ended == "completed"
    ref = simulate(World("paper-tracking", seed, 0.1), PIController(0.1), duration_s=duration)
    assert np.array_equal(np.array(maps), ref.map_mmhg, equal_nan=True)
    assert np.array_equal(np.array(cmds, dtype=np.float32).astype(float), ref.command_ml_h)
    assert dev_port.corrupted > 20 and rt_port.corrupted > 20
    c = rt.counters
    assert c.bad_crc + c.junk_bytes > 0 and c.seq_gaps > 0 and c.incomplete() > 0
    assert out["result"].counters["retransmits"] > 0 and c.retransmits > 0


def test_device_hello_announces_the_syringe_and_the_pump_maximum_its_pump_keeps_to():
    pair = PtyPair.open()
    ep = RuntimeSession(pair.leader_port())
    proc = spawn_device(
        pair,
        *("--duration", "0.5", "--pump-max-ml-h", "100"),
        *("--drug", "Norepinephrine", "--concentration-ug-ml", "16"),
    )
    peer = ep.handshake(Hello("pi"), timeout_s=30.0)
    assert (peer.drug, peer.concentration_ug_ml, peer.pump_max_ml_h) == ("norepinephrine", 16, 100)
    delivered = []
    for _ in range(peer.n_ticks):
        x = ep.wait_for_sample(10.0)
        assert x is not None
        if ep.pump_status is not None and ep.pump_status.tick == x.tick:
            delivered.append(ep.pump_status.delivered_ml_h)
        ep.send_command(x.tick, 120.0)  # above this pump's maximum: it clamps
    assert _finish(proc, pair, ep) == 0
    assert delivered and set(delivered) == {100.0}


def test_device_defaults_announce_the_shipped_designs_syringe_and_the_scenarios_pump():
    pair = PtyPair.open()
    ep = RuntimeSession(pair.leader_port())
    proc = spawn_device(pair, "--duration", "0.1")
    peer = ep.handshake(Hello("pi"), timeout_s=30.0)
    assert (peer.drug, peer.concentration_ug_ml, peer.pump_max_ml_h) == ("phenylephrine", 100, 120)
    x = ep.wait_for_sample(10.0)
    ep.send_command(x.tick, 0.0)
    assert _finish(proc, pair, ep) == 0


def test_device_pump_maximum_outside_the_pumps_range_exits_2_with_one_line(capsys):
    rc = device_main("device", ["--port", "x", "--no-signing", "--pump-max-ml-h", "0"])
    [line] = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert (
        line == "pressor device: --pump-max-ml-h = 0.0: must be a finite number in (0, 10000] ml/h"
    )


def test_realtime_device_with_a_1hz_monitor_sends_only_new_samples_and_applies_every_answer():
    from pressor.runtime.core.supervisor import Supervisor
    from pressor.runtime.core.supervisor_config import supervisor_config_for
    from pressor.runtime.shell.loop import Loop

    pair = PtyPair.open()
    ep = RuntimeSession(pair.leader_port())
    samples: list[int] = []
    statuses: list = []
    ep.on_message = lambda m: (
        samples.append(m.tick) if m.get_type() == "MAP_SAMPLE" else
        statuses.append(m) if m.get_type() == "PUMP_STATUS" else None
    )  # fmt: skip
    proc = spawn_device(pair, "--scenario", "bedside-monitor", "--duration", "3.0", "--realtime")
    peer = ep.handshake(Hello("pi"), timeout_s=30.0)
    pi = PIController(sample_period_s=peer.sample_period_s)
    loop = Loop(pi, Supervisor(supervisor_config_for(pi, peer.sensor_noise_mmhg)), ep)
    result = loop.run_realtime(peer.n_ticks)
    assert _finish(proc, pair, ep) == 0
    assert samples == [0, 10, 20]  # the monitor's updates only: no HELD repeats in real time
    assert result.ticks_in_state["AUTO"] == result.timing["ticks"]  # held, never stale
    # each period's command answers the latest sample, and the pump applies it: the delivered
    # rate follows the PI's integrator tick by tick, not only at the three updates
    delivered = [s.delivered_ml_h for s in statuses]
    assert len(set(delivered)) >= 20 and max(delivered) > 0.0
