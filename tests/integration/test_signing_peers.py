"""Signing between real peers: a mismatch is one clear error at the first frame, frames recorded
in an earlier run with the same key file are refused, and ``run`` / ``device`` sign by default."""

from __future__ import annotations

import time

import pytest

import pressor.link.signing as signing
from pressor.link import (
    MODE_AUTO,
    DeviceSession,
    Hello,
    PtyPair,
    RuntimeSession,
    Signing,
    SigningMismatch,
)
from pressor.link.dialect import pressor as mavlink
from tests.support.link_doubles import SinkPort, collect
from tests.support.sil_helpers import spawn_device


def _key(tmp_path, name: str, seed: int):
    return Signing.generate(seed=seed).write(tmp_path / name)


@pytest.mark.parametrize(
    ("device_args", "runtime_key", "needle"),
    [
        ((), "a", "the device's frames are unsigned"),
        # the other two wait the same 3 s on the same path: in the slow suite (README)
        pytest.param(
            ("--signing-key", "b"), "a", "the device signs with another key", marks=pytest.mark.slow
        ),
        pytest.param(
            ("--signing-key", "a"),
            None,
            "the device signs its frames but this end has no key",
            marks=pytest.mark.slow,
        ),
    ],
)
def test_a_signing_mismatch_fails_the_handshake_at_once_naming_signing(
    tmp_path, device_args, runtime_key, needle
):
    keys = {n: _key(tmp_path, n, seed) for n, seed in (("a", 1), ("b", 2))}
    args = [str(keys[a]) if a in keys else a for a in device_args]
    pair = PtyPair.open()
    proc = spawn_device(pair, "--duration", "5", *args)
    try:
        time.sleep(3.0)  # the device has started and sent its hellos
        sig = Signing.from_file(keys[runtime_key]) if runtime_key else None
        ep = RuntimeSession(pair.leader_port(), signing=sig)
        t0 = time.monotonic()
        with pytest.raises(SigningMismatch, match=needle):
            ep.handshake(Hello("pi"), timeout_s=30.0)
        assert time.monotonic() - t0 < 2.0
    finally:
        proc.kill()
        proc.wait()
        pair.close()


def test_the_device_names_signing_when_the_runtime_is_unsigned(tmp_path):
    key = _key(tmp_path, "a", 1)
    pair = PtyPair.open()
    proc = spawn_device(pair, "--duration", "5", "--signing-key", str(key))
    try:
        ep = RuntimeSession(pair.leader_port())
        t0 = time.monotonic()
        with pytest.raises(SigningMismatch):  # this end sees a signed hello it cannot check
            ep.handshake(Hello("pi"), timeout_s=30.0)
        ep.send_hello(Hello("pi"))  # an unsigned answer: the device refuses it at once
        _, err = proc.communicate(timeout=10)
        assert time.monotonic() - t0 < 10.0
    finally:
        proc.kill()
        pair.close()
    assert proc.returncode == 1
    [line] = err.strip().splitlines()
    assert line.startswith("pressor device: signing mismatch: the runtime's frames are unsigned")


def _run_frames(key: Signing) -> tuple[bytes, bytes]:
    """One run's frames with ``key``: the device's tick and the runtime's command."""
    dev = DeviceSession(SinkPort(), signing=key)
    rt = RuntimeSession(SinkPort(), signing=key)
    hb = dev.send_fields(mavlink.MAVLINK_MSG_ID_PRESSOR_HEARTBEAT, 0, 2, 1)
    cmd = rt.send_fields(mavlink.MAVLINK_MSG_ID_INFUSION_COMMAND, 0, 50.0, MODE_AUTO)
    return hb, cmd


def test_frames_recorded_in_an_earlier_run_with_the_same_key_file_are_refused(
    tmp_path, monkeypatch
):
    path = _key(tmp_path, "k", 7)
    # the earlier run, two minutes ago (its wall clock read two minutes less)
    monkeypatch.setattr(signing, "MAVLINK_EPOCH_UNIX_S", signing.MAVLINK_EPOCH_UNIX_S + 120)
    old_hb, old_cmd = _run_frames(Signing.from_file(path))
    monkeypatch.undo()
    # this run, same key file: the replayed frames are refused at both ends, genuine ones pass
    pump = DeviceSession(SinkPort(), signing=Signing.from_file(path))
    rt = RuntimeSession(SinkPort(), signing=Signing.from_file(path))
    got = collect(rt)
    pump.feed(old_cmd)
    rt.feed(old_hb)
    assert pump.wait_for_command(0, 0.0) is None and got == []
    assert pump.counters.refused_bad_signature == 1 and rt.counters.refused_bad_signature == 1
    with pytest.raises(SigningMismatch, match="replayed or more than a minute old"):
        rt.check_signing()
    new_hb, new_cmd = _run_frames(Signing.from_file(path))
    pump.feed(new_cmd)
    rt.feed(new_hb)
    assert pump.wait_for_command(0, 0.0) is not None and len(got) == 1


def test_key_files_sign_with_the_wall_clock_and_seeded_keys_with_the_run_clock(tmp_path):
    path = _key(tmp_path, "k", 3)
    stamp = int.from_bytes(_run_frames(Signing.from_file(path))[0][-12:-6], "little")
    assert abs(stamp / 100_000.0 - signing.wall_clock_s()) < 5.0
    seeded = int.from_bytes(_run_frames(Signing.generate(seed=3))[0][-12:-6], "little")
    assert seeded < 10  # run clock at 0 s


@pytest.mark.parametrize(
    ("device_key", "runtime_key"),
    [
        ("b", "a"),
        pytest.param(None, "a", marks=pytest.mark.slow),  # the same 3 s path: the slow suite
        pytest.param("a", None, marks=pytest.mark.slow),
    ],
    ids=str,
)
def test_both_real_ends_name_a_signing_mismatch_within_3_s(tmp_path, device_key, runtime_key):
    """``pressor device`` and ``pressor run`` on bridged ttys, keyed differently: each exits with
    one line naming the signing mismatch within 3 s of the other starting, neither waits out its
    30 s handshake for a hello."""
    import os
    import subprocess
    import sys

    from tests.support.sil_helpers import ROOT, bridged_ttys

    keys = {n: _key(tmp_path, n, seed) for n, seed in (("a", 1), ("b", 2))}

    def key_args(name):
        return ["--signing-key", str(keys[name])] if name else ["--no-signing"]

    env = dict(os.environ, CI="1", PYTHONPATH=str(ROOT))
    with bridged_ttys() as (device_port, runtime_port):
        base = [sys.executable, "-m", "pressor"]
        device = subprocess.Popen(
            [*base, "device", "--port", device_port, "--duration", "5", *key_args(device_key)],
            cwd=tmp_path, env=env, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        time.sleep(2.0)  # the device is up and repeating its hello
        t0 = time.monotonic()
        run = subprocess.Popen(
            [*base, "run", "--port", runtime_port, "--controller", "pi",
             *key_args(runtime_key)],
            cwd=tmp_path, env=env, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        try:
            run_err = run.communicate(timeout=30)[1]
            run_s = time.monotonic() - t0
            device_err = device.communicate(timeout=30)[1]
            device_s = time.monotonic() - t0
        finally:
            run.kill()
            device.kill()
    assert "signing mismatch" in run_err and run.returncode == 1, run_err
    # the device finds the mismatch itself (exit 1) or, unsigned, reads the runtime's refusal
    # naming it (exit 2)
    assert "signing mismatch" in device_err and device.returncode in (1, 2), device_err
    assert run_s < 3.0 + 2.0  # the runtime's start (imports) is part of its 3 s
    assert device_s - run_s < 3.0 and device_s < 6.0, (run_s, device_s)


def test_a_run_refused_at_its_command_line_tells_the_waiting_device(tmp_path):
    """``pressor run --controller lpv:norepinephrine`` without ``--weight-kg`` cannot start: it
    exits 2 with one line, and ``pressor device``, waiting in its handshake, is told the same line
    on the wire (PRESSOR_REFUSAL RUNTIME_CONFIG) and exits 2 with it within 3 s."""
    import os
    import subprocess
    import sys

    from tests.support.sil_helpers import ROOT, bridged_ttys

    key = _key(tmp_path, "a", 1)
    env = dict(os.environ, CI="1", PYTHONPATH=str(ROOT))
    base = [sys.executable, "-m", "pressor"]
    with bridged_ttys() as (device_port, runtime_port):
        device = subprocess.Popen(
            [*base, "device", "--port", device_port, "--duration", "5", "--signing-key", str(key)],
            cwd=tmp_path, env=env, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        time.sleep(2.0)
        t0 = time.monotonic()
        run = subprocess.run(
            [*base, "run", "--port", runtime_port, "--controller", "lpv:norepinephrine",
             "--signing-key", str(key)],
            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        try:
            device_err = device.communicate(timeout=30)[1]
            device_s = time.monotonic() - t0
        finally:
            device.kill()
    assert run.returncode == 2 and "--weight-kg: required" in run.stderr, run.stderr
    assert device.returncode == 2, device_err
    assert "refused by the runtime: --weight-kg: required" in device_err
    assert device_s < 3.0 + 5.0  # the runtime's own start (imports, the design) comes first
