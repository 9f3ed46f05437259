"""The clinician can always stop it: a real ``pressor run`` against a probing device on a real
pty, the clinician's lines on stdin or in the target file - ``stop`` (0 ml/h now, held),
``manual RATE``, ``resume`` - and the command SIGTERM ends on, chosen by ``--on-stop``."""

from __future__ import annotations

import os
import signal
import time

import pytest

from pressor.link import MODE_AUTO, MODE_MANUAL, MODE_SAFE, MODE_STOP
from tests.support.link_doubles import collect
from tests.support.probe_device import probe_run


def _say(run, line: str) -> None:
    run.proc.stdin.write(line + "\n")
    run.proc.stdin.flush()
    time.sleep(0.3)  # in the pipe before the next tick is sent


def test_stop_manual_and_resume_from_stdin_take_the_pump_and_give_it_back(tmp_path):
    with probe_run(tmp_path, "--target-mmhg", "75", "--target-stdin", n_ticks=200) as r:
        p = r.probe
        p.run(range(30), map_mmhg=60.0)
        _say(r, "stop")
        p.run(range(30, 80), map_mmhg=60.0)  # MAP still low: only the clinician ends a stop
        _say(r, "manual 12.5")
        p.run(range(80, 120), map_mmhg=60.0)
        _say(r, "resume")
        p.run(range(120, 200), map_mmhg=60.0)
        p.finish(200)
        code = r.wait()
    assert code == 0, r.err
    c = p.commands
    assert c[29].mode == MODE_AUTO and c[29].rate_ml_h > 0.0
    assert all(c[k].mode == MODE_STOP and c[k].rate_ml_h == 0.0 for k in range(30, 80))
    assert all(c[k].mode == MODE_MANUAL and c[k].rate_ml_h == 12.5 for k in range(80, 120))
    assert c[120].rate_ml_h == pytest.approx(12.5 + 0.5)  # resumed bumplessly from the manual rate
    assert c[199].mode == MODE_AUTO
    s = r.summary
    said = [(x["tick"], x["command"], x["state"]) for x in s["target"]["commands"]]
    assert said == [
        (30, "stop", "STOPPED"),
        (80, "manual", "MANUAL"),
        (120, "resume", "RECOVERING"),
    ]
    assert s["supervisor"]["ticks_in_state"]["STOPPED"] == 50
    assert s["supervisor"]["ticks_in_state"]["MANUAL"] == 40
    assert "stop (stdin) at 3 s, tick 30: AUTO -> STOPPED: 0 ml/h until resume" in r.err


def test_stop_holds_through_faults_and_a_bad_manual_rate_is_refused(tmp_path):
    with probe_run(tmp_path, "--target-mmhg", "75", "--target-stdin", n_ticks=90) as r:
        p = r.probe
        p.run(range(20), map_mmhg=60.0)
        _say(r, "stop")
        p.run(range(20, 40), map_mmhg=float("nan"))  # a fault while stopped: still 0
        _say(r, "manual 500")
        p.run(range(40, 60), map_mmhg=60.0)
        _say(r, "resume")
        p.run(range(60, 90), map_mmhg=60.0)
        p.finish(90)
        code = r.wait()
    assert code == 0, r.err
    c = p.commands
    assert all(c[k].mode == MODE_STOP and c[k].rate_ml_h == 0.0 for k in range(20, 60))
    assert "command from stdin refused: manual" in r.err and "[0, 120] ml/h" in r.err
    assert c[60].mode in (MODE_SAFE, MODE_AUTO)  # resumed: RECOVERING from 0


def test_stop_from_the_target_file_holds_until_resume_in_the_file(tmp_path):
    target = tmp_path / "target.txt"
    target.write_text("75\n")

    def write(text: str) -> None:  # as editors do: a new file renamed over the old one
        tmp = tmp_path / "target.new"
        tmp.write_text(text)
        os.replace(tmp, target)
        time.sleep(0.05)

    with probe_run(tmp_path, "--target-file", str(target), n_ticks=80) as r:
        p = r.probe
        p.run(range(20), map_mmhg=60.0)
        write("75\nstop\n")
        p.run(range(20, 50), map_mmhg=60.0)
        write("75\nresume\n")
        p.run(range(50, 80), map_mmhg=60.0)
        p.finish(80)
        code = r.wait()
    assert code == 0, r.err
    c = p.commands
    assert all(c[k].mode == MODE_STOP for k in range(20, 50))
    assert c[49].rate_ml_h == 0.0 and c[50].rate_ml_h == 0.5  # resumed: slewing back from 0
    said = [(x["command"], x["from"]) for x in r.summary["target"]["commands"]]
    assert said == [("stop", f"file {target}"), ("resume", f"file {target}")]


@pytest.mark.parametrize(
    ("on_stop", "mode"),
    [("zero", MODE_STOP), pytest.param("held", MODE_SAFE, marks=pytest.mark.slow)],
)
def test_sigterm_ends_on_the_command_on_stop_chooses(tmp_path, on_stop, mode):
    with probe_run(tmp_path, "--on-stop", on_stop) as r:
        p = r.probe
        p.run(range(30), map_mmhg=60.0)
        got = collect(p.ep)
        r.proc.send_signal(signal.SIGTERM)
        p.drain(2.0)
        code = r.wait()
    assert code == 143
    (last,) = [m for m in got if m.get_type() == "INFUSION_COMMAND"]
    assert last.tick == 30 and last.mode == mode
    expected = 0.0 if on_stop == "zero" else p.commands[29].rate_ml_h
    assert last.rate_ml_h == pytest.approx(expected)


def test_pressor_sil_takes_stop_and_resume_from_stdin(tmp_path):
    import json
    import subprocess
    import sys

    from pressor.link import read_tlog
    from pressor.link.dialect import pressor as mavlink
    from tests.support.sil_helpers import ROOT

    env = dict(os.environ, CI="1", PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "pressor", "sil", "--controller", "pi", "--realtime"]
    cmd += ["--duration", "12", "--clinician-stdin", "--tlog", "run.tlog", "--summary", "s.json"]
    cmd += ["--rrd", "r.rrd"]
    proc = subprocess.Popen(
        cmd, cwd=tmp_path, env=env, stdin=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        deadline = time.monotonic() + 60.0
        while not (tmp_path / "run.tlog").exists() or (tmp_path / "run.tlog").stat().st_size < 2000:
            assert proc.poll() is None and time.monotonic() < deadline, "the run did not start"
            time.sleep(0.1)
        time.sleep(2.0)
        proc.stdin.write("stop\n")
        proc.stdin.flush()
        time.sleep(2.0)
        proc.stdin.write("resume\n")
        proc.stdin.flush()
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    said = json.loads((tmp_path / "s.json").read_text())["clinician"]["commands"]
    assert [(x["command"], x["state"]) for x in said] == [
        ("stop", "STOPPED"),
        ("resume", "RECOVERING"),
    ]
    mav = mavlink.MAVLink(None)
    modes = [
        m.mode
        for m in (mav.decode(bytearray(f)) for _, f in read_tlog(tmp_path / "run.tlog"))
        if m.get_type() == "INFUSION_COMMAND"
    ]
    stopped = [k for k, mode in enumerate(modes) if mode == MODE_STOP]
    assert 10 <= len(stopped) <= 30  # about 2 s at 10 Hz, then resumed
    assert modes[-1] in (MODE_AUTO, MODE_SAFE)
