"""The loop cannot be killed by its disk, and the record of every run survives: a real
``pressor run`` against a probing device on a real pty, writing to a real full disk (a small
tmpfs; ``/dev/full`` where none can be mounted) and killed mid-run."""

from __future__ import annotations

import signal
import time
from dataclasses import replace

import pytest

from pressor.link import read_tlog
from pressor.link.dialect import pressor as mavlink
from tests.support.full_disk import fill, small_tmpfs
from tests.support.probe_device import probe_run


def test_a_disk_that_fills_under_the_tlog_and_the_recording_is_an_advisory_and_control_goes_on(
    tmp_path,
):
    """The .tlog and the .rrd each on its own 4 MiB tmpfs, both filled up at tick 100 (as a disk
    fills under a long run); where no tmpfs can be mounted the .tlog is /dev/full from the
    start."""
    with (
        small_tmpfs(tmp_path / "tlog", 4096) as (tdisk, kind),
        small_tmpfs(tmp_path / "rrd", 4096) as (rdisk, _),
    ):
        args = ["--tlog", str(tdisk / "run.tlog")]
        args += ["--rrd", str(rdisk / "run.rrd")] if kind == "tmpfs" else []
        with probe_run(tmp_path, *args, n_ticks=600) as r:
            p = r.probe
            p.run(range(100))  # the first ticks wait for the recorder to start (rerun's import)
            time.sleep(1.1)
            if kind == "tmpfs":  # durable within a second: the log of 100 ticks is on the disk
                assert (tdisk / "run.tlog").stat().st_size > 100 * 150
                fill(tdisk, 0)
                fill(rdisk, 0)
            late = []
            for k in range(100, 600):
                t0 = time.monotonic()
                p.tick(k)
                assert p.command(k, timeout_s=5.0) is not None, f"no command for tick {k} ({kind})"
                late.append(time.monotonic() - t0)
                if k % 100 == 0:
                    time.sleep(1.1)  # the writers find out within a second of wall time
            p.finish(600)
            code = r.wait()
        frames = list(read_tlog(tdisk / "run.tlog")) if kind == "tmpfs" else []
    assert "Traceback" not in r.err, r.err
    assert code == 1, r.err  # the run completed, its record did not
    assert "RECORD_ERROR: the tlog stopped at tick" in r.err
    assert "No space left on device" in r.err
    assert max(late) < 1.0
    s = r.summary
    assert s["ticks"] == 600 and s["ended"] == "completed"
    assert "No space left on device" in s["record"]["tlog"]
    assert s["supervisor"]["detections"]["RECORD_ERROR"] == 1
    assert s["supervisor"]["ticks_in_state"]["AUTO"] == 600  # advisory: control went on
    if kind == "tmpfs":  # what reached the disk before it filled is readable, frame by frame
        assert "recording" in s["record"]
        mav = mavlink.MAVLink(None)
        assert len(frames) > 100 * 4
        assert all(mav.decode(bytearray(f)) is not None for _, f in frames)


def test_a_recording_with_no_room_to_start_is_an_advisory_and_the_run_goes_on(tmp_path):
    with small_tmpfs(tmp_path / "disk", 512) as (disk, kind):
        if kind != "tmpfs":
            pytest.skip("no tmpfs can be mounted here")
        with probe_run(tmp_path, "--rrd", str(disk / "run.rrd"), n_ticks=30) as r:
            r.probe.run(range(30))
            r.probe.finish(30)
            code = r.wait()
    assert code == 1 and "Traceback" not in r.err, r.err
    assert "RECORD_ERROR: the recording stopped at tick 0" in r.err and "not started" in r.err
    assert r.summary["supervisor"]["ticks_in_state"]["AUTO"] == 30


def test_a_summary_that_cannot_be_written_is_one_line_and_exit_1(tmp_path):
    with small_tmpfs(tmp_path / "disk", 64) as (disk, kind):
        if kind == "tmpfs":
            fill(disk, 0)
        with probe_run(tmp_path, "--summary", str(disk / "s.json"), n_ticks=20) as r:
            r.probe.run(range(20))
            r.probe.finish(20)
            code = r.wait()
    assert code == 1 and "Traceback" not in r.err, r.err
    assert "summary" in r.err and "cannot be written: No space left on device" in r.err


def test_a_killed_run_leaves_its_tlog_readable_to_the_last_second(tmp_path):
    with probe_run(tmp_path) as r:
        p = r.probe
        p.run(range(50))
        time.sleep(1.2)  # the writer makes the log durable at least once a second
        r.proc.send_signal(signal.SIGKILL)
        r.wait()
    frames = list(read_tlog(tmp_path / "run.tlog"))
    mav = mavlink.MAVLink(None)
    ticks = [
        m.tick
        for m in (mav.decode(bytearray(f)) for _, f in frames)
        if m.get_type() == "INFUSION_COMMAND"
    ]
    assert ticks == list(range(50))
    assert not [q for q in tmp_path.iterdir() if q.name.startswith(".")]  # no hidden temp file


def test_a_run_that_is_refused_keeps_its_tlog_and_writes_its_summary(tmp_path):
    from pressor.link import LINK_LOCKSTEP, DeviceSession, Hello, PeerRefused, Signing, open_port
    from tests.support.scripted_run import SYRINGE, new_key, start_run
    from tests.support.sil_helpers import bridged_ttys

    key = new_key(tmp_path)
    with bridged_ttys() as (device_port, runtime_port):
        args = ["--summary", str(tmp_path / "s.json"), "--tlog", str(tmp_path / "run.tlog")]
        proc = start_run(runtime_port, key, tmp_path, *args)
        try:
            ep = DeviceSession(open_port(device_port), signing=Signing.from_file(key))
            hello = Hello("probe", 0, 0.1, 0.0, 0, LINK_LOCKSTEP, **SYRINGE)
            try:  # the runtime answers with its hello, then refuses the drug: the refusal can be
                # read in the handshake, or come right after it; the tlog below says which came
                ep.handshake(replace(hello, drug="norepinephrine"), timeout_s=60.0)
            except PeerRefused:
                pass
            proc.communicate(timeout=30)  # it ends by itself: no kill before its record is out
        finally:
            proc.kill()
    assert proc.returncode == 2
    frames = list(read_tlog(tmp_path / "run.tlog"))
    mav = mavlink.MAVLink(None)
    kinds = [mav.decode(bytearray(f)).get_type() for _, f in frames]
    assert "PRESSOR_REFUSAL" in kinds
    s = (tmp_path / "s.json").read_text()
    assert '"ticks": 0' in s and "norepinephrine" in s


def test_a_killed_sil_run_leaves_no_signing_key_in_its_temporary_folder(tmp_path):
    import os
    import re
    import subprocess
    import sys

    from tests.support.sil_helpers import ROOT

    tmpdir = tmp_path / "tmp"
    tmpdir.mkdir()
    env = dict(os.environ, CI="1", PYTHONPATH=str(ROOT), TMPDIR=str(tmpdir))
    cmd = [sys.executable, "-m", "pressor", "sil", "--controller", "pi", "--realtime"]
    cmd += ["--duration", "60", "--rrd", str(tmp_path / "r.rrd")]
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60.0
        while not any(p.name.startswith(".r.rrd") for p in tmp_path.iterdir()):
            assert proc.poll() is None and time.monotonic() < deadline, "the run did not start"
            time.sleep(0.1)
        time.sleep(1.0)  # the device runs, its key read
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    finally:
        proc.kill()
    folders = [p for p in tmpdir.iterdir() if p.name.startswith("pressor-sil-")]
    assert folders, "pressor sil made no temporary folder"  # the check below would be vacuous
    hexkey = re.compile(rb"^[0-9a-f]{64}\s*$", re.M)
    for f in (f for d in folders for f in d.rglob("*") if f.is_file()):
        assert f.name != "signing.key" and not hexkey.search(f.read_bytes()), f
