"""One rule for who may change the run: a real ``pressor run`` against a probing device on a real
pty. A mid-run hello is checked as the first one, the device's target is bound like the
clinician's, a pump status never sets the held command, and the runtime's own echoed frames are
not the device's liveness (docs/PROTOCOL.md, "A hello in the middle of a run")."""

from __future__ import annotations

import time

import pytest

from pressor.link import (
    LINK_REALTIME,
    MODE_AUTO,
    MODE_SAFE,
    REFUSAL_LINK_MODE,
    REFUSAL_SENSOR_NOISE,
    Hello,
    PumpStatus,
)
from pressor.link.dialect import pressor as mavlink
from tests.support.link_doubles import collect
from tests.support.probe_device import ID_SAMPLE, ID_SCHED, ID_TARGET, probe_run
from tests.support.scripted_run import SYRINGE, TS


def _refusals(got: list) -> list:
    return [m for m in got if m.get_type() == "PRESSOR_REFUSAL"]


def _reasons(probe) -> list[int]:
    return [reason for reason, _ in probe.refusals]


def test_a_mid_run_hello_that_changes_the_syringe_is_refused_and_holds_until_ack(tmp_path):
    changed = Hello(
        "probe", 0, TS, 1000.0, 0, drug="norepinephrine", concentration_ug_ml=200.0,
        pump_max_ml_h=50.0,
    )  # fmt: skip
    run_args = ("--target-mmhg", "75", "--target-stdin")
    with probe_run(tmp_path, *run_args, n_ticks=160) as r:
        p = r.probe
        p.run(range(30))
        got = collect(p.ep)
        p.ep.send_hello(changed)
        p.run(range(30, 100))
        r.proc.stdin.write("ack\n")
        r.proc.stdin.flush()
        time.sleep(0.5)
        p.run(range(100, 160))
        p.finish(160)
        code = r.wait()
    assert "Traceback" not in r.err, r.err
    (refusal,) = _refusals(got)
    assert _reasons(p) == [REFUSAL_SENSOR_NOISE]  # the first change, in the handshake's order
    for said in ("drug phenylephrine -> norepinephrine", "100 -> 200 ug/ml", "120 -> 50 ml/h"):
        assert said in refusal.text, said
    assert "DEVICE_CHANGED" in r.err and "norepinephrine" in r.err
    assert p.commands[29].mode == MODE_AUTO
    assert all(p.commands[k].mode == MODE_SAFE for k in range(31, 100))  # held, then FAILSAFE
    assert p.commands[159].mode == MODE_AUTO  # the clinician's ack resumed it
    s = r.summary
    assert code == 0, r.err
    assert s["syringe"] == {**SYRINGE, "pump_max_ml_h": 120.0}  # the run kept its first terms
    assert s["sensor_noise_mmhg"] == 0.0
    assert s["supervisor"]["detections"]["DEVICE_CHANGED"] == 1
    assert len(s["device_changes"]) == 1
    assert [a["accepted"] for a in s["target"]["acks"]] == [True]


def test_a_mid_run_hello_that_switches_to_real_time_is_refused_and_ticks_stay_lockstep(tmp_path):
    with probe_run(tmp_path, n_ticks=60) as r:
        p = r.probe
        p.run(range(20))
        got = collect(p.ep)
        p.ep.send_hello(Hello("probe", 0, TS, 0.0, 60, LINK_REALTIME, **SYRINGE))
        # lockstep assembly goes on: a sample waits for its tick's other frames
        p.ep.send_pump_status(PumpStatus(20, p.commands[19].rate_ml_h, 0.0, 0))
        p.ep.send_fields(ID_SAMPLE, 2.0, 20, 65.0, 0)
        assert p.command(20, timeout_s=1.0) is None
        p.ep.send_fields(ID_SCHED, 20, 0.5, 150.0, 30.0, 1, flush=False)
        p.ep.send_fields(ID_TARGET, 20, 80.0)
        assert p.command(20) is not None
        p.run(range(21, 60))
        p.finish(60)
        code = r.wait()
    assert code == 0, r.err
    assert [m.reason for m in _refusals(got)] == _reasons(p) == [REFUSAL_LINK_MODE]
    assert r.summary["mode"] == "lockstep"


def test_the_same_hello_again_mid_run_changes_nothing(tmp_path):
    with probe_run(tmp_path, n_ticks=40) as r:
        p = r.probe
        p.run(range(20))
        got = collect(p.ep)
        p.ep.send_hello(Hello("probe", 0, TS, 0.0, 40, **SYRINGE))
        p.run(range(20, 40))
        p.finish(40)
        code = r.wait()
    assert code == 0 and not _refusals(got) and not p.refusals
    assert all(p.commands[k].mode == MODE_AUTO for k in range(40))
    assert "DEVICE_CHANGED" not in r.summary["supervisor"]["detections"]


@pytest.mark.parametrize("target", [250.0, 20.0])
def test_the_devices_target_is_bound_like_the_clinicians(tmp_path, target):
    with probe_run(tmp_path, n_ticks=60) as r:
        p = r.probe
        p.run(range(20), target_mmhg=80.0)
        p.run(range(20, 40), target_mmhg=target)
        p.run(range(40, 60), target_mmhg=80.0)
        p.finish(60)
        code = r.wait()
    assert code == 0, r.err
    held = p.commands[19].rate_ml_h
    assert all(p.commands[k].mode == MODE_SAFE for k in range(20, 40))
    assert all(p.commands[k].rate_ml_h == pytest.approx(held) for k in range(20, 40))
    assert r.summary["supervisor"]["detections"]["TARGET_INVALID"] == 1


def test_a_pump_watchdog_status_never_sets_the_held_command(tmp_path):
    with probe_run(tmp_path, n_ticks=40) as r:
        p = r.probe
        p.run(range(20))
        held = p.commands[19].rate_ml_h
        watchdog = mavlink.PRESSOR_PUMP_ALARM_WATCHDOG
        p.run(range(20, 21), status=(120.0, watchdog))  # the pump says it runs 120 ml/h
        p.run(range(21, 40))
        p.finish(40)
        code = r.wait()
    assert code == 0, r.err
    assert held < 100.0
    assert p.commands[20].mode == MODE_SAFE
    assert p.commands[20].rate_ml_h == pytest.approx(held)  # not re-based to the pump's 120
    assert max(p.commands[k].rate_ml_h for k in range(20, 40)) < 100.0


def test_the_runtimes_own_frames_echoed_back_are_not_the_devices_liveness(tmp_path):
    """Real time: the device stops sending and echoes back every byte the runtime sends (a line
    in cooked mode); the runtime must see the silence: LINK_LOSS, FAILSAFE within ~1 s."""
    with probe_run(tmp_path, "--realtime", "--ticks", "80", realtime=True) as r:
        p = r.probe
        ep = p.ep
        t0 = time.monotonic()
        for k in range(30):  # 3 s of a 10 Hz monitor
            ep.clock.t = k * TS
            if k:
                ep.send_pump_status(PumpStatus(k, 0.0, 0.0, 0), flush=False)
            ep.send_fields(ID_SCHED, k, 0.5, 150.0, 30.0, 1, flush=False)
            ep.send_fields(ID_TARGET, k, 80.0, flush=False)
            ep.send_fields(ID_SAMPLE, k * TS, k, 65.0, 0)
            time.sleep(max(0.0, t0 + (k + 1) * TS - time.monotonic()))
        silent_at = time.monotonic()
        parser = mavlink.MAVLink(None)
        first_safe = None
        while time.monotonic() - silent_at < 3.0:
            data = ep.port.read(ep.port.in_waiting or 1)
            if not data:
                continue
            ep.port.write(data)  # the echo
            for m in parser.parse_buffer(data) or []:
                if (
                    m.get_type() == "INFUSION_COMMAND"
                    and m.mode == MODE_SAFE
                    and first_safe is None
                ):
                    first_safe = time.monotonic() - silent_at
        r.proc.kill()
        r.wait()
    assert first_safe is not None and first_safe < 1.5, first_safe
