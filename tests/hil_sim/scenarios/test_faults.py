"""Device-side injection: sensor, pump and scheduling faults in the world; link faults on the port."""

from __future__ import annotations

import math

import numpy as np

from pressor.baselines.pi import PIController
from pressor.contracts.faults import parse_fault
from pressor.hil_sim.devices.pump import ALARM_OCCLUSION, ALARM_RESERVOIR_EMPTY
from pressor.hil_sim.devices.sensor import QUALITY_WAVEFORM
from pressor.hil_sim.episode import simulate
from pressor.hil_sim.scenarios.faults import LinkFaultPort, LinkFaults, split_frames
from pressor.hil_sim.world import World
from pressor.link import DeviceSession, RuntimeSession
from tests.support.link_doubles import loop_pair, tick_inputs

TS = 0.1


def run(faults, n=200, rate=30.0, scenario="paper-tracking"):
    w = World(scenario, 2, TS, faults=tuple(parse_fault(f, i) for i, f in enumerate(faults)))
    obs, status = [], []
    for _ in range(n):
        obs.append(w.observe())
        w.apply_command(rate)
        status.append(w.advance())
    return w, obs, status


def test_sensor_faults_change_the_reading_exactly_in_their_window():
    _, clean, _ = run([])
    _, o, _ = run(
        ["sensor-nan:2,1", "sensor-flush:5,1", "sensor-range:8,1", "sensor-disconnect:11,1"]
    )
    m = np.array([x.map_mmhg for x in o])
    ref = np.array([x.map_mmhg for x in clean])
    assert np.all(np.isnan(m[20:30])) and not np.isnan(m[19]) and not np.isnan(m[30])
    assert np.all(m[50:60] == 300.0) and np.all(m[80:90] == 400.0) and np.all(m[110:120] == 0.0)
    outside = np.r_[0:20, 30:50, 60:80, 90:110, 120:200]
    np.testing.assert_array_equal(m[outside], ref[outside])  # nothing else changed
    assert all(x.quality == 0 for x in o)  # none of these is flagged by the monitor


def test_flatline_sticks_at_the_last_value_and_the_monitor_flags_it_after_the_delay():
    _, o, _ = run(["sensor-flatline:5,2,flag_after_s=0.5"], n=100, rate=120.0)
    m = np.array([x.map_mmhg for x in o])
    q = np.array([x.quality for x in o])
    assert np.all(m[50:70] == m[49])
    assert np.all(q[:55] == 0) and np.all(q[55:70] == QUALITY_WAVEFORM) and np.all(q[70:] == 0)


def test_pump_occlusion_and_empty_stop_delivery_with_alarms_then_resume():
    _, _, st = run(["pump-occlusion:2,1", "pump-empty:5,1"])
    d = np.array([s.delivered_ml_h for s in st])
    a = np.array([s.alarms for s in st])
    # status i is after advancing tick i; tick 20..29 occluded, 50..59 empty
    assert np.all(d[20:30] == 0.0) and np.all(a[20:30] & ALARM_OCCLUSION)
    assert np.all(d[50:60] == 0.0) and np.all(a[50:60] & ALARM_RESERVOIR_EMPTY)
    assert d[19] == d[30] == d[60] == 30.0 and a[30] == a[60] == 0


def test_pump_mismatch_and_ignore_change_delivery_not_the_command():
    w = World("paper-tracking", 2, TS, faults=(parse_fault("pump-ignore:1,1"),))
    for k in range(30):
        w.observe()
        w.apply_command(10.0 if k < 10 else 50.0)
        s = w.advance()
        if k == 15:
            assert s.delivered_ml_h == 10.0 and w.last_command_ml_h == 50.0
    assert s.delivered_ml_h == 50.0
    _, _, st = run(["pump-mismatch:1,1,factor=0.5"], n=30)
    assert st[15].delivered_ml_h == 15.0 and st[25].delivered_ml_h == 30.0


def test_sched_faults_rewrite_what_the_device_reports():
    _, clean, _ = run([], n=80)
    _, o, _ = run(["sched-out-of-box:1,1", "sched-jump:3,1,amplitude=0.1", "sched-missing:5,1"], 80)
    assert all(x.K == 5.0 for x in o[10:20])  # the default reported K, outside the box
    dk = [o[k].K - clean[k].K for k in range(30, 40)]
    assert np.allclose(dk, [0.1, -0.1] * 5, atol=1e-6)
    assert all(math.isnan(x.K) and not x.sched_valid for x in o[50:60])
    assert o[60].sched_valid and o[60].K == clean[60].K


def test_world_without_faults_is_unchanged_and_faulted_runs_repeat_exactly():
    a = simulate(World("paper-tracking", 3, TS), PIController(TS), 60.0)
    b = simulate(World("paper-tracking", 3, TS, faults=()), PIController(TS), 60.0)
    np.testing.assert_array_equal(a.command_ml_h, b.command_ml_h)
    f = (parse_fault("sensor-damped:10,20"), parse_fault("pump-mismatch:30,10", 1))
    c = simulate(World("paper-tracking", 3, TS, faults=f), PIController(TS), 60.0)
    d = simulate(World("paper-tracking", 3, TS, faults=f), PIController(TS), 60.0)
    np.testing.assert_array_equal(c.command_ml_h, d.command_ml_h)
    assert not np.array_equal(a.command_ml_h, c.command_ml_h)


def _link_bytes(kind: str, seed: int) -> bytes:
    a, b = loop_pair()
    tick = [0]
    faults = LinkFaults([parse_fault(f"{kind}:0,100,seed={seed}")], TS)
    port = LinkFaultPort(a, faults, lambda: tick[0])
    ep = DeviceSession(port)
    for k in range(20):
        tick[0] = k
        ep.send_tick(tick_inputs(k, k * TS, 80.0, 0, 90.0, 0.5, 150.0, 30.0, True))
    out = b""
    while b.in_waiting:
        out += b.read(b.in_waiting)
    return out


def test_link_faults_are_seeded_repeatable_and_first_write_is_always_hit():
    clean = _link_bytes("link-flip", 0)  # window from tick 0: compare with a no-fault stream
    a, b = loop_pair()
    ep = DeviceSession(a)
    for k in range(20):
        ep.send_tick(tick_inputs(k, k * TS, 80.0, 0, 90.0, 0.5, 150.0, 30.0, True))
    reference = b""
    while b.in_waiting:
        reference += b.read(b.in_waiting)
    for kind in ("link-flip", "link-drop", "link-duplicate", "link-garbage"):
        one, two, other = _link_bytes(kind, 1), _link_bytes(kind, 1), _link_bytes(kind, 2)
        assert one == two and one != reference, kind
        assert one != other or kind == "link-drop", kind
    first = split_frames(reference)[:3]
    assert b"".join(split_frames(clean)[:3]) != b"".join(first)  # tick 0 is hit


def test_runtime_parser_survives_every_link_fault_and_accepts_only_good_frames():
    for kind in ("link-flip", "link-drop", "link-duplicate", "link-garbage"):
        stream = _link_bytes(kind, 5)
        a, b = loop_pair()
        rt = RuntimeSession(a, complete_ticks=False)
        rt.feed(stream)
        ticks = []
        while (x := rt.next_sample()) is not None:
            ticks.append(x.tick)
            assert x.map_mmhg == 80.0 and x.target_mmhg == 90.0
        assert ticks == sorted(set(ticks)) and len(ticks) >= 1
        c = rt.counters
        assert c.bad_crc + c.junk_bytes + c.seq_gaps + c.duplicates > 0, kind
