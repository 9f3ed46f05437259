"""FrameCodec through real sessions and ports: corruption, gaps, stalls, resync, fast codec vs pymavlink."""

from __future__ import annotations

import pytest

from pressor.link import (
    MODE_SAFE,
    STATE_FINISHED,
    STATE_RUNNING,
    DeviceSession,
    ManualClock,
    RuntimeSession,
    Signing,
)
from pressor.link.dialect import pressor as mavlink
from tests.support.link_doubles import FaultyPort, SinkPort, collect, drain, loop_pair, tick_inputs


def _pressor_heartbeat(tx: DeviceSession, tick: int, state: int) -> None:
    """One PRESSOR_HEARTBEAT frame in one write (``send_heartbeat`` adds the standard one)."""
    tx.send_fields(mavlink.MAVLINK_MSG_ID_PRESSOR_HEARTBEAT, tick, tx.ROLE, state)


@pytest.mark.parametrize("every", [2, 3, 7])
def test_a_corrupted_byte_every_n_frames_loses_only_that_frame_and_is_counted(every):
    a, b = loop_pair()
    faulty = FaultyPort(a, corrupt_every=every, seed=every)
    tx = DeviceSession(faulty)
    rx = RuntimeSession(b)
    got = collect(rx)
    n = 300
    for k in range(n):
        _pressor_heartbeat(tx, k, STATE_RUNNING)  # one frame per write
        if k % 20 == 19:
            rx.poll(0.0)
    tx.port = a  # a clean last frame, so a gap before it is visible
    _pressor_heartbeat(tx, n, STATE_FINISHED)
    drain(rx)
    rx.wait_for_sample(0.02)  # a timeout abandons any stalled partial frame
    drain(rx)
    corrupted = {k for k in range(n) if (k + 1) % every == 0}
    assert faulty.corrupted == len(corrupted)
    assert [m.tick for m in got] == [k for k in range(n + 1) if k not in corrupted]
    c = rx.counters
    assert c.bad_crc + c.resyncs >= 1
    assert c.seq_gaps == len(corrupted) and c.frames_lost == len(corrupted)
    assert c.frames_received == n + 1 - len(corrupted)


def test_dropped_frames_are_counted_as_sequence_gaps_including_wraparound():
    a, b = loop_pair()
    tx = DeviceSession(FaultyPort(a, drop_every=5))
    rx = RuntimeSession(b)
    got = collect(rx)
    for k in range(601):  # > 2 wraps of the 8-bit sequence number; frame 600 is not dropped
        _pressor_heartbeat(tx, k, STATE_RUNNING)
        if k % 50 == 0:
            rx.poll(0.0)
    drain(rx)
    dropped = 600 // 5
    assert [m.tick for m in got] == [k for k in range(601) if (k + 1) % 5]
    assert rx.counters.seq_gaps == dropped and rx.counters.frames_lost == dropped
    assert rx.counters.bad_crc == 0


def test_a_frame_cut_off_mid_way_is_abandoned_on_timeout_and_the_stream_resumes():
    a, b = loop_pair()
    rx = RuntimeSession(b)
    dev = DeviceSession(a, clock=ManualClock(0.0))
    frame = dev.send(dev.codec.mav.pressor_heartbeat_encode(1, 2, 1), flush=False)
    dev.discard_queued()
    a.write(frame[:-3])  # the peer stalls inside a frame
    assert rx.wait_for_sample(0.05) is None
    assert rx.counters.timeouts == 1 and rx.counters.resyncs == 1
    dev.send_tick(tick_inputs(4, 0.4, 81.0, 0, 90.0, 0.5, 120.0, 20.0, True))
    x = rx.wait_for_sample(1.0)
    assert x is not None and x.tick == 4 and x.map_mmhg == 81.0 and x.sched_tick == 4


@pytest.mark.parametrize("delta", [8, -1, 200])
def test_a_corrupted_length_byte_loses_only_its_own_frame(delta):
    # pymavlink's parse_buffer would skip `length` bytes and swallow the following frames
    a, b = loop_pair()
    rx = RuntimeSession(b)
    got = collect(rx)
    dev = DeviceSession(a)
    frames = [
        dev.send(dev.codec.mav.pressor_hello_encode(0.1, k, 0, 0.0, 2, 0, 1, b"s"), flush=False)
        for k in range(5)
    ]
    dev.discard_queued()
    bad = bytearray(frames[1])
    bad[1] = (bad[1] + delta) % 256
    a.write(b"".join([frames[0], bytes(bad), *frames[2:]]))
    drain(rx)
    assert [m.patient_seed for m in got] == [0, 2, 3, 4]
    assert rx.counters.bad_crc + rx.counters.junk_bytes > 0
    assert rx.counters.seq_gaps == 1 and rx.counters.frames_lost == 1


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
    fast = DeviceSession(SinkPort(), signing=sig, clock=ManualClock(12.5))
    slow = DeviceSession(SinkPort(), signing=sig, clock=ManualClock(12.5))
    rx = RuntimeSession(SinkPort(), signing=sig)
    got = collect(rx)
    for name, args in _FAST_CASES:
        msg = getattr(slow.codec.mav, name)(*args)
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
