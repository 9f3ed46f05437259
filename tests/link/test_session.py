"""Runtime and device sessions over real ports: lockstep, timeouts, retransmits, determinism, pty, tlog."""

from __future__ import annotations

import threading
import time

import pytest

from pressor.link import (
    MODE_AUTO,
    STATE_FINISHED,
    DeviceSession,
    Hello,
    HelloRefused,
    LinkClosedError,
    ManualClock,
    PtyPair,
    PumpStatus,
    RuntimeSession,
    Signing,
    TlogWriter,
    read_tlog,
    register_dialect_with_mavutil,
)
from pressor.link.dialect import pressor as mavlink
from tests.support.link_doubles import FaultyPort, collect, drain, loop_pair, tick_inputs


def test_a_stalled_peer_times_out_and_is_counted():
    a, b = loop_pair()
    rx = RuntimeSession(b)
    t0 = time.monotonic()
    assert rx.wait_for_sample(0.1) is None
    assert time.monotonic() - t0 >= 0.1
    assert rx.counters.timeouts == 1
    dev = DeviceSession(a)
    assert dev.wait_for_command(0, 0.05) is None
    assert dev.counters.timeouts == 1


def _lockstep_exchange(tmp_path, tag: str, key_seed: int, n: int = 40) -> tuple[bytes, bytes]:
    """Device and runtime threads in lockstep over loop://, both signing; returns both tlogs."""
    a, b = loop_pair()
    dclock = ManualClock()
    dlog = TlogWriter(tmp_path / f"{tag}-device.tlog")
    rlog = TlogWriter(tmp_path / f"{tag}-runtime.tlog")
    dev = DeviceSession(a, signing=Signing.generate(seed=key_seed), clock=dclock, tlog=dlog)
    rt = RuntimeSession(b, signing=Signing.generate(seed=key_seed), tlog=rlog)
    errors: list = []

    def device() -> None:
        try:
            dev.handshake(Hello("paper-tracking", 3, 0.1, 0.0, n))
            for k in range(n):
                dclock.t = 0.1 * k
                dev.send_tick(
                    tick_inputs(k, dclock.t, 80.0 + 0.1 * k, 0, 90.0, 0.5, 150.0, 30.0, True)
                )
                cmd = dev.wait_for_command(k, 2.0)
                assert cmd is not None
                dev.send_pump_status(PumpStatus(k + 1, cmd.rate_ml_h, 0.01 * k, 0), flush=False)
            dev.send_heartbeat(n, STATE_FINISHED)
        except BaseException as exc:  # surfaced in the main thread
            errors.append(exc)

    t = threading.Thread(target=device)
    t.start()
    rt.handshake(Hello("pi"))
    for _ in range(n):
        x = rt.wait_for_sample(2.0)
        assert x is not None
        rt.send_command(x.tick, 3.0 + 0.5 * (90.0 - x.map_mmhg), MODE_AUTO)
    t.join()
    drain(rt)
    assert not errors, errors
    assert rt.peer_heartbeat == (n, STATE_FINISHED)
    assert dev.counters.refused_unsigned == dev.counters.refused_bad_signature == 0
    dlog.close()
    rlog.close()
    return dlog.path.read_bytes(), rlog.path.read_bytes()


def test_signed_lockstep_runs_are_byte_identical_with_the_same_key(tmp_path):
    first = _lockstep_exchange(tmp_path, "one", key_seed=5)
    second = _lockstep_exchange(tmp_path, "two", key_seed=5)
    other = _lockstep_exchange(tmp_path, "three", key_seed=6)
    assert first == second
    assert first[0] != other[0]  # the signature really depends on the key
    frames = [f for _, f in read_tlog_bytes(first[0])]
    assert frames and all(f[2] & 1 for f in frames), "every frame on the link is signed"


def read_tlog_bytes(data: bytes):
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "x.tlog"
        p.write_bytes(data)
        return list(read_tlog(p))


def test_tlog_is_readable_by_pymavlink_mavutil_with_run_clock_timestamps(tmp_path):
    device_log, _ = _lockstep_exchange(tmp_path, "log", key_seed=5, n=10)
    path = tmp_path / "log-device.tlog"
    mavutil = register_dialect_with_mavutil()
    log = mavutil.mavlink_connection(str(path), dialect="pressor")
    samples = []
    while True:
        m = log.recv_match(type="MAP_SAMPLE")
        if m is None:
            break
        samples.append((m.tick, round(m._timestamp, 6)))
    log.close()
    assert samples == [(k, round(0.1 * k, 6)) for k in range(10)]


def test_runtime_and_device_in_lockstep_over_a_real_pty_pair():
    pair = PtyPair.open()
    rt = RuntimeSession(pair.leader_port())
    n = 50
    result: dict = {}

    def device() -> None:
        dev = DeviceSession(pair.follower_port())
        dev.handshake(Hello("paper-tracking", 3, 0.1, 1.0, n))
        rates = []
        for k in range(n):
            dev.send_tick(tick_inputs(k, 0.1 * k, 70.0 + k, 0, 85.0, 0.5, 150.0, 30.0, True))
            cmd = dev.wait_for_command(k, 2.0)
            rates.append(cmd.rate_ml_h if cmd else None)
        dev.send_heartbeat(n, STATE_FINISHED)
        result["rates"] = rates
        result["counters"] = dev.snapshot()
        dev.close()

    t = threading.Thread(target=device)
    t.start()
    peer = rt.handshake(Hello("pi"), timeout_s=5.0)
    assert (peer.name, peer.patient_seed, peer.n_ticks) == ("paper-tracking", 3, n)
    maps = []
    for _ in range(n):
        x = rt.wait_for_sample(2.0)
        maps.append(x.map_mmhg)
        rt.send_command(x.tick, float(x.tick) * 0.5)
    t.join()
    pair.close_follower()
    with pytest.raises(LinkClosedError):
        for _ in range(100):  # drains the final heartbeat, then sees the closed peer
            rt.poll(0.05)
    assert rt.peer_heartbeat == (n, STATE_FINISHED)
    assert maps == [70.0 + k for k in range(n)]
    assert result["rates"] == [0.5 * k for k in range(n)]
    assert result["counters"].bad_crc == 0 and result["counters"].seq_gaps == 0
    assert rt.counters.timeouts == 0 and rt.counters.junk_bytes == 0


def test_a_retransmitted_tick_is_answered_again_with_the_same_command():
    a, b = loop_pair()
    dev = DeviceSession(FaultyPort(a))
    rt = RuntimeSession(b)
    dev.send_tick(tick_inputs(0, 0.0, 80.0, 0, 90.0, 0.5, 150.0, 30.0, True))
    x = rt.wait_for_sample(1.0)
    rt.send_command(x.tick, 12.0)
    assert dev.wait_for_command(0, 1.0).rate_ml_h == 12.0
    dev.send_tick(
        tick_inputs(0, 0.0, 80.0, 0, 90.0, 0.5, 150.0, 30.0, True)
    )  # as if the answer was lost
    assert rt.wait_for_sample(0.05) is None  # not handed to the loop twice ...
    cmd = dev.wait_for_command(0, 1.0)  # ... but answered again
    assert cmd is not None and cmd.rate_ml_h == 12.0
    assert rt.counters.duplicates == 1 and rt.counters.retransmits == 1
    assert mavlink.MAVLINK_MSG_ID_INFUSION_COMMAND == 45005


def test_a_world_tick_and_pump_status_arrive_at_the_runtime_as_equal_messages():
    # one type per message on both ends: what the world builds is what the runtime receives
    from pressor.hil_sim.world import World

    world = World("paper-tracking", 3, 0.1)
    a, b = loop_pair()
    dev, rt = DeviceSession(a), RuntimeSession(b)
    for _ in range(3):
        sent = world.observe()
        dev.send_tick(sent)
        assert rt.wait_for_sample(1.0) == sent
        rt.send_command(sent.tick, 7.5)
        cmd = dev.wait_for_command(sent.tick, 1.0)
        assert cmd is not None
        world.apply_command(cmd.rate_ml_h)
        status = world.advance()
        dev.send_pump_status(status)
        deadline = time.monotonic() + 5.0  # a loaded machine may take a while to pass the frame
        while rt.pump_status != status and time.monotonic() < deadline:
            rt.poll(0.05)
        assert rt.pump_status == status and status.delivered_ml_h == 7.5


def test_a_handshake_with_a_peer_of_the_same_role_fails():
    a, b = loop_pair()
    DeviceSession(b).send_hello(Hello("twin"))  # a second device where the runtime should be
    with pytest.raises(HelloRefused, match="peer announced role 2 .device., expected 1"):
        DeviceSession(a).handshake(Hello("paper-tracking"), timeout_s=1.0)


def test_each_heartbeat_is_preceded_by_a_standard_mavlink_heartbeat_for_ground_tools():
    a, b = loop_pair()
    dev = DeviceSession(a)
    rt = RuntimeSession(b)
    got = collect(rt)
    dev.send_heartbeat(7, STATE_FINISHED)
    drain(rt)
    std, ours = got
    assert std.get_type() == "HEARTBEAT" and ours.get_type() == "PRESSOR_HEARTBEAT"
    assert (std.type, std.autopilot, std.mavlink_version) == (
        mavlink.MAV_TYPE_GENERIC,
        mavlink.MAV_AUTOPILOT_INVALID,
        3,
    )
    assert std.system_status == mavlink.MAV_STATE_STANDBY and std.custom_mode == STATE_FINISHED
    assert rt.peer_heartbeat == (7, STATE_FINISHED)


def test_the_hello_carries_drug_concentration_and_pump_maximum_both_ways():
    a, b = loop_pair()
    dev, rt = DeviceSession(a), RuntimeSession(b)
    syringe = {"drug": "phenylephrine", "concentration_ug_ml": 100.0}
    dev.send_hello(Hello("paper-tracking", 3, pump_max_ml_h=110.5, **syringe))
    got = rt.wait_for_hello(1.0)
    assert (got.name, got.patient_seed, got.protocol_version) == ("paper-tracking", 3, 2)
    assert (got.drug, got.concentration_ug_ml, got.pump_max_ml_h) == ("phenylephrine", 100.0, 110.5)
    rt.send_hello(Hello("pi", pump_max_ml_h=120.0, **syringe))
    back = dev.wait_for_hello(1.0)
    assert (back.name, back.drug, back.pump_max_ml_h) == ("pi", "phenylephrine", 120.0)


def test_a_protocol_1_peer_still_decodes_and_is_refused_naming_the_version():
    # the new hello fields are MAVLink 2 extensions: they do not enter CRC_EXTRA, so version 1's
    # hello (the same frame without them) still decodes and the handshake can say what is wrong
    assert mavlink.MAVLink_pressor_hello_message.crc_extra == 238  # version 1's
    a, b = loop_pair()
    DeviceSession(b).send_hello(Hello("old-device", protocol_version=1))
    with pytest.raises(HelloRefused, match="peer protocol_version 1, expected 2"):
        RuntimeSession(a).handshake(Hello("pi"), timeout_s=1.0)
