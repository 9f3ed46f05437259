"""LinkEndpoint over real ports: corruption, gaps, stalls, signing, determinism, pty, tlog."""

from __future__ import annotations

import threading
import time

import pytest

from link import (
    MODE_AUTO,
    MODE_SAFE,
    STATE_FINISHED,
    STATE_RUNNING,
    FaultyPort,
    Hello,
    LinkClosedError,
    LinkEndpoint,
    ManualClock,
    PtyPair,
    Signing,
    TlogWriter,
    loop_pair,
    read_tlog,
    register_dialect_with_mavutil,
)
from link.dialect import pressor as mavlink


def _collect(ep: LinkEndpoint) -> list:
    got: list = []
    ep.on_message = got.append
    return got


def _drain(ep: LinkEndpoint, quiet_s: float = 0.05) -> None:
    while ep.poll(quiet_s):
        pass


@pytest.mark.parametrize("every", [2, 3, 7])
def test_a_corrupted_byte_every_n_frames_loses_only_that_frame_and_is_counted(every):
    a, b = loop_pair()
    faulty = FaultyPort(a, corrupt_every=every, seed=every)
    tx = LinkEndpoint(faulty, "device")
    rx = LinkEndpoint(b, "runtime")
    got = _collect(rx)
    n = 300
    for k in range(n):
        tx.send_heartbeat(k, STATE_RUNNING)  # one frame per write
        if k % 20 == 19:
            rx.poll(0.0)
    tx.port = a  # a clean last frame, so a gap before it is visible
    tx.send_heartbeat(n, STATE_FINISHED)
    _drain(rx)
    rx.wait_for_sample(0.02)  # a timeout abandons any stalled partial frame
    _drain(rx)
    corrupted = {k for k in range(n) if (k + 1) % every == 0}
    assert faulty.corrupted == len(corrupted)
    assert [m.tick for m in got] == [k for k in range(n + 1) if k not in corrupted]
    c = rx.counters
    assert c.bad_crc + c.resyncs >= 1
    assert c.seq_gaps == len(corrupted) and c.frames_lost == len(corrupted)
    assert c.frames_received == n + 1 - len(corrupted)


def test_dropped_frames_are_counted_as_sequence_gaps_including_wraparound():
    a, b = loop_pair()
    tx = LinkEndpoint(FaultyPort(a, drop_every=5), "device")
    rx = LinkEndpoint(b, "runtime")
    got = _collect(rx)
    for k in range(601):  # > 2 wraps of the 8-bit sequence number; frame 600 is not dropped
        tx.send_heartbeat(k, STATE_RUNNING)
        if k % 50 == 0:
            rx.poll(0.0)
    _drain(rx)
    dropped = 600 // 5
    assert [m.tick for m in got] == [k for k in range(601) if (k + 1) % 5]
    assert rx.counters.seq_gaps == dropped and rx.counters.frames_lost == dropped
    assert rx.counters.bad_crc == 0


def test_a_stalled_peer_times_out_and_is_counted():
    a, b = loop_pair()
    rx = LinkEndpoint(b, "runtime")
    t0 = time.monotonic()
    assert rx.wait_for_sample(0.1) is None
    assert time.monotonic() - t0 >= 0.1
    assert rx.counters.timeouts == 1
    dev = LinkEndpoint(a, "device")
    assert dev.wait_for_command(0, 0.05) is None
    assert dev.counters.timeouts == 1


def test_a_frame_cut_off_mid_way_is_abandoned_on_timeout_and_the_stream_resumes():
    a, b = loop_pair()
    rx = LinkEndpoint(b, "runtime")
    dev = LinkEndpoint(a, "device", clock=ManualClock(0.0))
    frame = dev.send(dev._mav.pressor_heartbeat_encode(1, 2, 1), flush=False)
    dev._tx.clear()
    a.write(frame[:-3])  # the peer stalls inside a frame
    assert rx.wait_for_sample(0.05) is None
    assert rx.counters.timeouts == 1 and rx.counters.resyncs == 1
    dev.send_tick(4, 0.4, 81.0, 0, 90.0, 0.5, 120.0, 20.0, True)
    x = rx.wait_for_sample(1.0)
    assert x is not None and x.tick == 4 and x.map_mmhg == 81.0 and x.sched_tick == 4


@pytest.mark.parametrize("delta", [8, -1, 200])
def test_a_corrupted_length_byte_loses_only_its_own_frame(delta):
    # pymavlink's parse_buffer would skip `length` bytes and swallow the following frames
    a, b = loop_pair()
    rx = LinkEndpoint(b, "runtime")
    got = _collect(rx)
    dev = LinkEndpoint(a, "device")
    frames = [
        dev.send(dev._mav.pressor_hello_encode(0.1, k, 0, 0.0, 2, 0, 1, b"s"), flush=False)
        for k in range(5)
    ]
    dev._tx.clear()
    bad = bytearray(frames[1])
    bad[1] = (bad[1] + delta) % 256
    a.write(b"".join([frames[0], bytes(bad), *frames[2:]]))
    _drain(rx)
    assert [m.patient_seed for m in got] == [0, 2, 3, 4]
    assert rx.counters.bad_crc + rx.counters.junk_bytes > 0
    assert rx.counters.seq_gaps == 1 and rx.counters.frames_lost == 1


def _signed_pump_and_runtime(runtime_signing):
    a, b = loop_pair()
    pump = LinkEndpoint(a, "device", signing=Signing.generate(seed=1))
    rt = LinkEndpoint(b, "runtime", signing=runtime_signing)
    return pump, rt


def test_the_pump_refuses_and_counts_unsigned_commands():
    pump, rt = _signed_pump_and_runtime(None)
    rt.send_command(0, 50.0, MODE_AUTO)
    assert pump.wait_for_command(0, 0.1) is None
    assert pump.counters.refused_unsigned == 1 and pump.counters.frames_received == 0


def test_the_pump_refuses_and_counts_commands_signed_with_a_wrong_key():
    pump, rt = _signed_pump_and_runtime(Signing.generate(seed=2))
    rt.send_command(0, 50.0, MODE_AUTO)
    assert pump.wait_for_command(0, 0.1) is None
    assert pump.counters.refused_bad_signature == 1 and pump.counters.frames_received == 0


def test_the_pump_refuses_a_replayed_signed_command_and_accepts_the_genuine_one():
    pump, rt = _signed_pump_and_runtime(Signing.generate(seed=1))
    rt.send_command(0, 50.0, MODE_SAFE)
    cmd = pump.wait_for_command(0, 1.0)
    assert cmd is not None and cmd.rate_ml_h == 50.0 and cmd.mode == MODE_SAFE
    frame = rt.send(rt._mav.infusion_command_encode(1, 99.0, MODE_AUTO), flush=False)
    rt._tx.clear()
    rt.port.write(frame)
    assert pump.wait_for_command(1, 1.0) is not None
    rt.port.write(frame)  # the same bytes again: an old timestamp
    assert pump.wait_for_command(1, 0.05) is None
    assert pump.counters.refused_bad_signature == 1


def test_a_key_file_in_hex_or_raw_loads_and_a_bad_one_names_the_file(tmp_path):
    s = Signing.generate(seed=3)
    assert Signing.from_file(s.write(tmp_path / "k.hex")).key == s.key
    (tmp_path / "k.bin").write_bytes(s.key)
    assert Signing.from_file(tmp_path / "k.bin").key == s.key
    (tmp_path / "short").write_bytes(b"abc")
    with pytest.raises(ValueError, match="short"):
        Signing.from_file(tmp_path / "short")
    assert Signing.generate().key != Signing.generate().key  # per-run keys differ


def _lockstep_exchange(tmp_path, tag: str, key_seed: int, n: int = 40) -> tuple[bytes, bytes]:
    """Device and runtime threads in lockstep over loop://, both signing; returns both tlogs."""
    a, b = loop_pair()
    dclock = ManualClock()
    dlog = TlogWriter(tmp_path / f"{tag}-device.tlog")
    rlog = TlogWriter(tmp_path / f"{tag}-runtime.tlog")
    dev = LinkEndpoint(
        a, "device", signing=Signing.generate(seed=key_seed), clock=dclock, tlog=dlog
    )
    rt = LinkEndpoint(b, "runtime", signing=Signing.generate(seed=key_seed), tlog=rlog)
    errors: list = []

    def device() -> None:
        try:
            dev.handshake(Hello("paper-tracking", 3, 0.1, 0.0, n))
            for k in range(n):
                dclock.t = 0.1 * k
                dev.send_tick(k, dclock.t, 80.0 + 0.1 * k, 0, 90.0, 0.5, 150.0, 30.0, True)
                cmd = dev.wait_for_command(k, 2.0)
                assert cmd is not None
                dev.send_pump_status(k + 1, cmd.rate_ml_h, 0.01 * k, 0, flush=False)
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
    _drain(rt)
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
    rt = LinkEndpoint(pair.leader_port(), "runtime")
    n = 50
    result: dict = {}

    def device() -> None:
        dev = LinkEndpoint(pair.follower_port(), "device")
        dev.handshake(Hello("paper-tracking", 3, 0.1, 1.0, n))
        rates = []
        for k in range(n):
            dev.send_tick(k, 0.1 * k, 70.0 + k, 0, 85.0, 0.5, 150.0, 30.0, True)
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
    dev = LinkEndpoint(FaultyPort(a), "device")
    rt = LinkEndpoint(b, "runtime")
    dev.send_tick(0, 0.0, 80.0, 0, 90.0, 0.5, 150.0, 30.0, True)
    x = rt.wait_for_sample(1.0)
    rt.send_command(x.tick, 12.0)
    assert dev.wait_for_command(0, 1.0).rate_ml_h == 12.0
    dev.send_tick(0, 0.0, 80.0, 0, 90.0, 0.5, 150.0, 30.0, True)  # as if the answer was lost
    assert rt.wait_for_sample(0.05) is None  # not handed to the loop twice ...
    cmd = dev.wait_for_command(0, 1.0)  # ... but answered again
    assert cmd is not None and cmd.rate_ml_h == 12.0
    assert rt.counters.duplicates == 1 and rt.counters.retransmits == 1
    assert mavlink.MAVLINK_MSG_ID_INFUSION_COMMAND == 45005


def test_a_signed_frame_with_a_corrupted_timestamp_does_not_lock_out_later_frames():
    # the CRC does not cover the signature block; pymavlink alone would store the bogus (huge)
    # timestamp and then refuse every genuine frame as a replay
    a, b = loop_pair()
    key = Signing.generate(seed=4)
    dev = LinkEndpoint(a, "device", signing=key)
    rt = LinkEndpoint(b, "runtime", signing=key)
    got = _collect(rt)
    frames = [dev.send(dev._mav.pressor_heartbeat_encode(k, 2, 1), flush=False) for k in range(4)]
    dev._tx.clear()
    bad = bytearray(frames[1])
    bad[-7] ^= 0x80  # the top byte of the 48-bit signing timestamp
    a.write(b"".join([frames[0], bytes(bad), *frames[2:]]))
    _drain(rt)
    assert [m.tick for m in got] == [0, 2, 3]
    assert rt.counters.refused_bad_signature == 1


class _Sink:
    """A port that keeps what is written (no reads): frames as the endpoint emits them."""

    timeout = 0.01
    in_waiting = 0

    def __init__(self) -> None:
        self.data = bytearray()

    def write(self, data: bytes) -> int:
        self.data += data
        return len(data)

    def read(self, size: int = 1) -> bytes:
        return b""

    def close(self) -> None:
        pass


_FAST_CASES = [
    ("pressor_heartbeat_encode", (7, 2, 1)),
    ("scheduling_params_encode", (7, 0.5, 150.25, 20.0, 1)),
    ("map_target_encode", (7, 75.0)),
    ("map_sample_encode", (0.7, 7, 71.5, 0)),
    ("map_sample_encode", (0.0, 0, 0.0, 0)),  # all-zero payload: truncated to one byte
    ("infusion_command_encode", (7, 12.5, MODE_SAFE)),
    ("pump_status_encode", (7, 12.5, 3.25, 4)),
]


@pytest.mark.parametrize("signed", [False, True])
def test_fast_codec_frames_are_byte_identical_to_pymavlink_pack_and_decode(signed):
    sig = Signing.generate(5) if signed else None
    fast = LinkEndpoint(_Sink(), "device", signing=sig, clock=ManualClock(12.5))
    slow = LinkEndpoint(_Sink(), "device", signing=sig, clock=ManualClock(12.5))
    rx = LinkEndpoint(_Sink(), "runtime", signing=sig)
    got = _collect(rx)
    for name, args in _FAST_CASES:
        msg = getattr(slow._mav, name)(*args)
        want = slow.send(msg)
        assert fast.send_fields(msg.id, *args) == want, name
        ref = mavlink.MAVLink(None, 1, 1)
        if sig is not None:
            ref.signing.secret_key = sig.key
        decoded = ref.decode(bytearray(want))
        rx.feed(want)
        assert got[-1].get_type() == decoded.get_type()
        assert got[-1].to_dict() == decoded.to_dict(), name
    assert rx.counters.frames_received == len(_FAST_CASES)


def test_fast_decoder_refuses_forged_and_unsigned_frames_like_pymavlink():
    key = Signing.generate(1)
    rx = LinkEndpoint(_Sink(), "device", signing=key)
    forger = LinkEndpoint(_Sink(), "runtime", signing=Signing.generate(2))
    plain = LinkEndpoint(_Sink(), "runtime")
    good = LinkEndpoint(_Sink(), "runtime", signing=key)
    rx.feed(forger.send_fields(mavlink.MAVLINK_MSG_ID_INFUSION_COMMAND, 0, 50.0, MODE_AUTO))
    rx.feed(plain.send_fields(mavlink.MAVLINK_MSG_ID_INFUSION_COMMAND, 0, 50.0, MODE_AUTO))
    frame = bytearray(good.send_fields(mavlink.MAVLINK_MSG_ID_INFUSION_COMMAND, 0, 5.0, MODE_AUTO))
    frame[12] ^= 0x40  # payload bit flipped: CRC fails
    rx.feed(bytes(frame))
    rx.feed(good.send_fields(mavlink.MAVLINK_MSG_ID_INFUSION_COMMAND, 0, 5.0, MODE_AUTO))
    c = rx.counters
    assert (c.refused_bad_signature, c.refused_unsigned, c.bad_crc) == (1, 1, 1)
    assert rx.wait_for_command(0, 0.0).rate_ml_h == 5.0


def test_signature_timestamp_rules_match_pymavlink_for_genuine_frames():
    # stamps (run time, s) of frames from two streams (link ids 0 and 1): in order, a replay, an
    # equal stamp, a new stream more than a minute behind the receiver's own stamp, one just
    # inside the minute
    key = Signing.generate(seed=9)
    plan = [(0, 100.0), (0, 100.5), (0, 100.2), (0, 100.5), (1, 20.0), (1, 41.0), (0, 101.0)]
    frames = []
    for link_id, t in plan:
        tx = LinkEndpoint(
            _Sink(), "device", signing=Signing(key.key, link_id), clock=ManualClock(t)
        )
        frames.append(tx.send_fields(mavlink.MAVLINK_MSG_ID_PRESSOR_HEARTBEAT, 1, 2, 1))
    ours = LinkEndpoint(_Sink(), "runtime", signing=key)
    ref = mavlink.MAVLink(None, 1, 1)
    ref.signing.secret_key = key.key
    verdicts = []
    for frame in frames:
        refused = ours.counters.refused_bad_signature
        ours.feed(frame)
        try:
            ref.decode(bytearray(frame))
            want = True
        except mavlink.MAVError:
            want = False
        got = ours.counters.refused_bad_signature == refused
        verdicts.append((got, want))
    assert [g for g, _ in verdicts] == [w for _, w in verdicts]
    assert [g for g, _ in verdicts] == [True, True, False, False, False, True, True]
    assert ours._mav.signing.timestamp == ref.signing.timestamp
