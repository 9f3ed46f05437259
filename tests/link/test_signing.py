"""Signing: the pump refuses unsigned, forged and replayed frames; key files; timestamp rules."""

from __future__ import annotations

import pytest

from pressor.link import (
    MODE_AUTO,
    MODE_SAFE,
    DeviceSession,
    ManualClock,
    RuntimeSession,
    Signing,
)
from pressor.link.dialect import pressor as mavlink
from pressor.link.signing import key_file_warnings
from tests.support.link_doubles import SinkPort, collect, drain, loop_pair


def _signed_pump_and_runtime(runtime_signing):
    a, b = loop_pair()
    pump = DeviceSession(a, signing=Signing.generate(seed=1))
    rt = RuntimeSession(b, signing=runtime_signing)
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
    frame = rt.send(rt.codec.mav.infusion_command_encode(1, 99.0, MODE_AUTO), flush=False)
    rt.discard_queued()
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


def test_whitespace_inside_a_hex_key_file_is_ignored(tmp_path):
    s = Signing.generate(seed=5)
    h = s.key.hex()
    grouped = " ".join(h[i : i + 8] for i in range(0, 64, 8))  # pasted in groups
    lines = "\n".join(h[i : i + 16] for i in range(0, 64, 16))  # or over lines
    for name, text in (("groups", grouped), ("lines", f"  {lines}\r\n"), ("tabs", "\t".join(h))):
        (tmp_path / name).write_text(text)
        assert Signing.from_file(tmp_path / name).key == s.key, name


def test_a_hex_key_with_a_non_hex_character_is_refused_naming_the_file(tmp_path):
    (tmp_path / "typo").write_text("g" + Signing.generate(seed=6).key.hex()[1:] + "\n")
    with pytest.raises(ValueError, match="typo: signing key has 65 bytes"):
        Signing.from_file(tmp_path / "typo")


def test_key_file_warnings_name_a_file_every_user_can_read_and_an_all_zero_key(tmp_path):
    good = Signing.generate(seed=7).write(tmp_path / "good")  # mode 0600, as keygen writes it
    assert key_file_warnings(good, Signing.from_file(good).key) == []
    shared = Signing.generate(seed=7).write(tmp_path / "shared")
    shared.chmod(0o644)
    [line] = key_file_warnings(shared, Signing.from_file(shared).key)
    assert str(shared) in line and "every user (mode 0644)" in line and "chmod 600" in line
    zero = Signing(bytes(32)).write(tmp_path / "zero")
    [line] = key_file_warnings(zero, Signing.from_file(zero).key)
    assert str(zero) in line and "zero" in line and "pressor keygen" in line


def test_a_signed_frame_with_a_corrupted_timestamp_does_not_lock_out_later_frames():
    # the CRC does not cover the signature block; pymavlink alone would store the bogus (huge)
    # timestamp and then refuse every genuine frame as a replay
    a, b = loop_pair()
    key = Signing.generate(seed=4)
    dev = DeviceSession(a, signing=key)
    rt = RuntimeSession(b, signing=key)
    got = collect(rt)
    frames = [
        dev.send(dev.codec.mav.pressor_heartbeat_encode(k, 2, 1), flush=False) for k in range(4)
    ]
    dev.discard_queued()
    bad = bytearray(frames[1])
    bad[-7] ^= 0x80  # the top byte of the 48-bit signing timestamp
    a.write(b"".join([frames[0], bytes(bad), *frames[2:]]))
    drain(rt)
    assert [m.tick for m in got] == [0, 2, 3]
    assert rt.counters.refused_bad_signature == 1


def test_fast_decoder_refuses_forged_and_unsigned_frames_like_pymavlink():
    key = Signing.generate(1)
    rx = DeviceSession(SinkPort(), signing=key)
    forger = RuntimeSession(SinkPort(), signing=Signing.generate(2))
    plain = RuntimeSession(SinkPort())
    good = RuntimeSession(SinkPort(), signing=key)
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
        tx = DeviceSession(SinkPort(), signing=Signing(key.key, link_id), clock=ManualClock(t))
        frames.append(tx.send_fields(mavlink.MAVLINK_MSG_ID_PRESSOR_HEARTBEAT, 1, 2, 1))
    ours = RuntimeSession(SinkPort(), signing=key)
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
    assert ours.codec.mav.signing.timestamp == ref.signing.timestamp
