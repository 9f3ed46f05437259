"""The bedside loop cannot be killed by its inputs: a real ``pressor run`` against a probing device
on a real pty sends each bad input of issue 39 and the loop turns it into a fault state, never an
exception, and goes on answering (docs/PROTOCOL.md, "What the runtime does on a bad input")."""

from __future__ import annotations

import math
import os
import signal
import time

import pytest

from pressor.link import MODE_SAFE, STATE_FAULT, read_tlog
from pressor.link.dialect import pressor as mavlink
from tests.support.link_doubles import collect
from tests.support.probe_device import probe_run

TS = 0.1


def _assert_no_traceback(text: str) -> None:
    assert "Traceback" not in text, text


@pytest.mark.parametrize(
    ("case", "sim_time_s"),
    [("backwards", 0.5), ("nan", math.nan), ("inf", math.inf), ("ahead", 1e6)],
)
def test_a_sample_with_a_bad_time_is_a_sample_time_fault_and_the_loop_goes_on(
    tmp_path, case, sim_time_s
):
    with probe_run(tmp_path, n_ticks=40) as r:
        p = r.probe
        p.run(range(20))
        p.tick(20, sim_time_s=sim_time_s)
        bad = p.command(20)
        p.run(range(21, 40))
        p.finish(40)
        code = r.wait()
    _assert_no_traceback(r.err)
    assert code == 0, r.err
    assert bad is not None and bad.mode == MODE_SAFE  # held, not crashed
    s = r.summary
    assert s["ticks"] == 40 and s["sample_time_faults"] == 1
    assert s["supervisor"]["detections"]["SAMPLE_TIME"] == 1
    assert s["metrics"]["overshoot_pct"] is None or math.isfinite(s["metrics"]["overshoot_pct"])
    assert [ts for ts, _ in read_tlog(tmp_path / "run.tlog")] == sorted(
        ts for ts, _ in read_tlog(tmp_path / "run.tlog")
    )  # the log's clock never ran backwards


def test_a_time_that_lags_a_tick_jump_is_a_sample_time_fault(tmp_path):
    """Tick 20 jumps to 1020 while its time stays at 2.1 s (tick 21's): the loop runs the silent
    ticks on the tick's own clock and holds on the sample, instead of raising."""
    with probe_run(tmp_path, n_ticks=1030) as r:
        p = r.probe
        p.run(range(20))
        p.tick(1020, sim_time_s=2.1)
        assert p.command(1020) is not None
        p.run(range(1021, 1030))
        p.finish(1030)
        code = r.wait()
    _assert_no_traceback(r.err)
    assert code == 0, r.err
    assert r.summary["supervisor"]["detections"]["SAMPLE_TIME"] == 1


@pytest.mark.parametrize("jump", [10**6, 2**32 - 30])
def test_a_tick_that_jumps_by_a_million_or_to_2_32_is_answered_at_once(tmp_path, jump):
    """The silent ticks of a jump are run one by one only until the supervisor's output settles
    (FAILSAFE after the link loss, its ramp done); the rest cost one step."""
    with probe_run(tmp_path) as r:
        p = r.probe
        p.run(range(20))
        k = 20 + jump if jump < 2**31 else jump
        t0 = time.monotonic()
        p.tick(k)
        cmd = p.command(k, timeout_s=30.0)
        latency_s = time.monotonic() - t0
        p.run(range(k + 1, k + 10))
        p.finish(k + 10)
        code = r.wait()
    _assert_no_traceback(r.err)
    assert code == 0, r.err
    assert cmd is not None and latency_s < 1.0, latency_s
    s = r.summary
    assert sum(s["supervisor"]["ticks_in_state"].values()) == k + 10
    assert s["ticks"] < 2000  # the record holds the settling ticks, not the million
    assert s["supervisor"]["detections"]["LINK_LOSS"] == 1


def test_an_infinite_map_and_an_impossible_delivered_rate_leave_a_finite_summary(tmp_path):
    with probe_run(tmp_path, n_ticks=40) as r:
        p = r.probe
        p.run(range(20))
        p.run(range(20, 21), map_mmhg=math.inf)
        p.run(range(21, 22), status=(3.4e38, 0))  # float32's largest: no pump delivers it
        p.run(range(22, 40))
        p.finish(40)
        code = r.wait()
    _assert_no_traceback(r.err)
    assert code == 0, r.err
    s = r.summary
    m = s["metrics"]
    assert m["max_rate_ml_h"] <= 120.0 and m["drug_total_ml"] < 1.0
    assert m["overshoot_pct"] is None or math.isfinite(m["overshoot_pct"])
    assert s["supervisor"]["detections"]["MAP_NAN"] == 1
    assert s["supervisor"]["detections"]["PUMP_MISMATCH"] == 1


def test_a_device_that_stalls_gets_the_safe_command_and_the_run_keeps_its_record(tmp_path):
    with probe_run(tmp_path, "--stall-timeout", "1") as r:
        p = r.probe
        p.run(range(30))
        got = collect(p.ep)
        p.drain(3.0)  # silent: the runtime gives up after 1 s
        code = r.wait()
    assert code == 1 and "device sent no sample" in r.err
    _assert_no_traceback(r.err)
    cmds = [m for m in got if m.get_type() == "INFUSION_COMMAND"]
    beats = [m for m in got if m.get_type() == "PRESSOR_HEARTBEAT"]
    assert cmds and cmds[0].tick == 30 and cmds[0].mode == MODE_SAFE
    assert cmds[0].rate_ml_h == pytest.approx(p.commands[29].rate_ml_h)  # the held rate
    assert beats and beats[-1].state == STATE_FAULT
    s = r.summary
    assert s["ticks"] == 30 and s["ended"].startswith("failed: device sent no sample")
    assert "DeviceStalled" in s["error"]
    frames = list(read_tlog(tmp_path / "run.tlog"))  # kept in place, every frame readable
    mav = mavlink.MAVLink(None)
    last = mav.decode(bytearray(frames[-1][1]))
    assert last.get_type() == "PRESSOR_HEARTBEAT" and last.state == STATE_FAULT


def test_an_internal_error_sends_the_safe_command_before_the_process_dies(tmp_path):
    plugin = "tests.support.controller_plugins:Crashes:at=25"
    with probe_run(tmp_path, "--controller", plugin) as r:
        p = r.probe
        p.run(range(24))
        got = collect(p.ep)
        p.tick(24)
        p.drain(3.0)
        code = r.wait()
    assert code != 0 and "the loop died" in r.err
    cmds = [m for m in got if m.get_type() == "INFUSION_COMMAND"]
    assert [(c.tick, c.mode) for c in cmds] == [(24, MODE_SAFE)]  # the tick it died in
    assert cmds[0].rate_ml_h == pytest.approx(p.commands[23].rate_ml_h)
    assert [m.state for m in got if m.get_type() == "PRESSOR_HEARTBEAT"] == [STATE_FAULT]
    assert (tmp_path / "run.tlog").stat().st_size > 0


def test_a_target_file_replaced_by_a_fifo_never_blocks_the_tick_and_sigterm_works(tmp_path):
    target = tmp_path / "target.txt"
    target.write_text("70\n")
    with probe_run(tmp_path, "--target-file", str(target)) as r:
        p = r.probe
        p.run(range(10))
        fifo = tmp_path / "fifo"
        os.mkfifo(fifo)
        os.replace(fifo, target)  # a FIFO no one writes: opening it would block
        late = []
        for k in range(10, 40):
            t0 = time.monotonic()
            p.tick(k)
            assert p.command(k, timeout_s=5.0) is not None, k
            late.append(time.monotonic() - t0)
        t0 = time.monotonic()
        r.proc.send_signal(signal.SIGTERM)
        code = r.wait(timeout_s=10.0)
        stop_s = time.monotonic() - t0
    assert max(late) < 1.0, max(late)
    assert code == 143 and stop_s < 3.0, (code, stop_s, r.err)
    assert "not a regular file" in r.err
    _assert_no_traceback(r.err)
    assert r.summary["interrupted"] is True and r.summary["target"]["refused"] == 1


def test_a_fifo_as_the_starting_target_file_is_refused_at_once(tmp_path):
    from tests.support.sil_helpers import pressor

    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    out = pressor(
        "run", "--port", "/dev/null", "--target-file", str(fifo), cwd=tmp_path, timeout=20
    )
    assert out.returncode == 2
    assert out.stderr.strip().endswith("not a regular file (a FIFO)"), out.stderr
