"""Lockstep tick assembly at the runtime's end of a real pty: a tick's frames in any order, only
what the controller and schedule need required, lost frames recovered by the device's resend and
counted by cause."""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
import pytest

from pressor.hil_sim.devices.device import run_device
from pressor.hil_sim.episode import simulate
from pressor.hil_sim.world import World
from pressor.link import (
    STATE_FINISHED,
    DeviceSession,
    Hello,
    ManualClock,
    PtyPair,
    PumpStatus,
    RuntimeSession,
    TickInputs,
    open_port,
)
from pressor.link.dialect import pressor as mavlink
from pressor.runtime.estimation.sources import make_schedule
from pressor.runtime.inputs.controller_loader import load_controller
from pressor.runtime.session import run_runtime
from tests.support.link_doubles import tick_inputs
from tests.support.sil_helpers import lockstep_run_config

_IDS = {
    "sample": mavlink.MAVLINK_MSG_ID_MAP_SAMPLE,
    "target": mavlink.MAVLINK_MSG_ID_MAP_TARGET,
    "sched": mavlink.MAVLINK_MSG_ID_SCHEDULING_PARAMS,
    "status": mavlink.MAVLINK_MSG_ID_PUMP_STATUS,
}


def _send(dev: DeviceSession, x: TickInputs, status: PumpStatus | None, order: tuple) -> None:
    """Tick ``x``'s frames (and the pump status, if any) in ``order``, in one write."""
    values = {
        "sample": (x.sim_time_s, x.tick, x.map_mmhg, x.quality),
        "target": (x.tick, x.target_mmhg),
        "sched": (x.tick, x.K, x.T_s, x.tau_s, int(x.sched_valid)),
        "status": None
        if status is None
        else (status.tick, status.delivered_ml_h, status.volume_ml, status.alarms),
    }
    for name in order:
        if values[name] is not None:
            dev.send_fields(_IDS[name], *values[name], flush=False)
    dev.flush()


def _lockstep_device(
    pair: PtyPair, n: int, order: tuple, lose: set, out: dict, status_ahead: int = 1
) -> None:
    """A device that sends each tick's frames in ``order`` and the pump status after each
    command, numbered ``status_ahead`` ticks after the one answered (the protocol says 1);
    ``lose`` = {(tick, frame name)} left out of the tick's first transmission.
    It resends a tick once (without the pump status, like ``pressor device``) if no command came
    within 0.2 s, else gives up."""
    retransmit_s = 0.2
    dev = DeviceSession(pair.follower_port())
    out["retransmits"] = 0
    try:
        dev.handshake(Hello("paper-tracking", 3, 0.1, 0.0, n), timeout_s=5.0)
        status: PumpStatus | None = None
        for k in range(n):
            x = tick_inputs(k, 0.1 * k, 70.0 + k, target_mmhg=85.0 + k, K=0.5 + 0.01 * k)
            first = tuple(f for f in order if (k, f) not in lose)
            _send(dev, x, status, first)
            cmd = dev.wait_for_command(k, retransmit_s)
            if cmd is None:
                out["retransmits"] += 1
                _send(dev, x, None, order)
                cmd = dev.wait_for_command(k, retransmit_s)
                if cmd is None:
                    out["gave_up_at"] = k
                    return
            status = PumpStatus(k + status_ahead, cmd.rate_ml_h, 0.1 * k, 0)
        dev.send_heartbeat(n, STATE_FINISHED)
    finally:
        dev.close()


def _run(
    order: tuple, lose: frozenset = frozenset(), n: int = 50, status_ahead: int = 1, **session: Any
):
    """Drive the device above from a runtime session; returns the ticks, the pump status at hand
    at each tick, the wall time of the ticks (s), the runtime session and the device's account."""
    pair = PtyPair.open()
    rt = RuntimeSession(pair.leader_port(), **session)
    out: dict = {}
    t = threading.Thread(
        target=_lockstep_device, args=(pair, n, order, set(lose), out, status_ahead)
    )
    t.start()
    try:
        rt.handshake(Hello("pi"), timeout_s=5.0)
        ticks, statuses = [], []
        t0 = time.monotonic()
        for _ in range(n):
            x = rt.wait_for_sample(2.0)
            if x is None:
                break
            ticks.append(x)
            statuses.append(rt.pump_status)
            rt.send_command(x.tick, 1.0 + x.tick)
        wall_s = time.monotonic() - t0
    finally:
        t.join(10)
        pair.close()
    return ticks, statuses, wall_s, rt, out


def _assert_ticks_as_sent(ticks: list, n: int) -> None:
    assert [x.tick for x in ticks] == list(range(n))
    for x in ticks:
        k = x.tick
        assert x.map_mmhg == 70.0 + k and x.target_mmhg == 85.0 + k
        assert x.K == np.float32(0.5 + 0.01 * k) and x.sched_tick == x.target_tick == k


def test_a_device_sending_sample_then_target_then_sched_runs_50_ticks_without_a_resend():
    order = ("sample", "target", "sched", "status")
    ticks, statuses, wall_s, rt, out = _run(order)
    assert "gave_up_at" not in out and out["retransmits"] == 0
    _assert_ticks_as_sent(ticks, 50)
    # the pump status sent after the sample still belongs to its tick: the pump checks run (from
    # tick 2: the runtime waits for a status once the device has sent the first one)
    assert statuses[0] is None
    assert [s.tick for s in statuses[2:]] == list(range(2, 50))
    assert [s.delivered_ml_h for s in statuses[2:]] == [1.0 + k for k in range(1, 49)]
    assert wall_s < 2.0  # each resend would cost 0.2 s
    c = rt.counters
    assert c.duplicates == c.old_ticks == c.incomplete() == c.timeouts == 0
    assert c.misnumbered_status == 0


@pytest.mark.parametrize(
    ("order", "lost", "cause"),
    [
        (("status", "sched", "target", "sample"), (3, "sched"), "incomplete_sched"),
        (("sample", "target", "sched", "status"), (4, "target"), "incomplete_target"),
        (("sample", "sched", "status", "target"), (4, "sched"), "incomplete_sched"),
        (("status", "sched", "target", "sample"), (5, "status"), "incomplete_status"),
    ],
)
def test_a_tick_missing_a_lost_frame_completes_after_the_device_resends_it_counted_by_cause(
    order, lost, cause
):
    n = 12
    ticks, statuses, _, rt, out = _run(order, frozenset({lost}), n=n)
    assert "gave_up_at" not in out and out["retransmits"] == 1
    _assert_ticks_as_sent(ticks, n)
    c = rt.counters
    assert c.as_dict()[cause] == 1 and c.incomplete() == 1
    assert c.duplicates == 1  # the resent sample
    k = lost[0]
    held = [s.tick for s in statuses[1:]]
    if cause == "incomplete_status":  # a lost status is not resent: its tick goes without it
        assert held == [j if j != k else k - 1 for j in range(1, n)]
    else:
        assert held == list(range(1, n))


def test_a_pump_status_numbered_k_instead_of_k_plus_1_is_not_waited_for():
    ticks, statuses, wall_s, rt, out = _run(("sample", "target", "sched", "status"), status_ahead=0)
    assert out["retransmits"] == 0 and wall_s < 2.0
    _assert_ticks_as_sent(ticks, 50)
    assert all(s is None or s.tick < x.tick for s, x in zip(statuses, ticks, strict=True))
    assert rt.counters.incomplete() == 0
    # not silent: each unusable status is counted and raises the runtime's LINK_ERRORS alarm
    assert rt.counters.misnumbered_status == 49  # ticks 1..49 each brought the previous status
    assert rt.counters.discarded() == 49


def test_without_required_sched_and_target_the_sample_alone_completes_a_tick():
    # only the sample (and the pump status once seen) is needed: the device's target and
    # scheduling frames of the tick are kept when they came before the tick was complete, else NaN
    ticks, _, _, _, out = _run(
        ("sample", "status", "target", "sched"), require_sched=False, require_target=False
    )
    assert out["retransmits"] == 0 and [x.tick for x in ticks] == list(range(50))
    assert all(np.isnan(x.target_mmhg) and x.target_tick == -1 for x in ticks)
    assert all(np.isnan(x.K) and x.sched_tick == -1 and not x.sched_valid for x in ticks)
    ticks, _, _, _, _ = _run(("target", "sample", "sched"), require_sched=False, n=5)
    assert [(x.target_tick, x.sched_tick) for x in ticks] == [(k, -1) for k in range(5)]


class SampleFirstNoSchedDevice(DeviceSession):
    """A monitor and pump that know no K, T, τ and send each tick as MAP sample, target, then
    the pump status of the tick (held back from its usual place before the sample)."""

    _status: PumpStatus | None = None

    def send_pump_status(self, status: PumpStatus, *, flush: bool = True) -> None:
        self._status = status

    def _flush_status(self) -> None:
        if self._status is not None:
            super().send_pump_status(self._status, flush=False)
            self._status = None

    def send_tick(self, inputs: TickInputs, *, flush: bool = True) -> None:
        k = inputs.tick
        send = self.send_fields
        send(mavlink.MAVLINK_MSG_ID_MAP_SAMPLE, inputs.sim_time_s, k, inputs.map_mmhg,
             inputs.quality, flush=False)  # fmt: skip
        send(mavlink.MAVLINK_MSG_ID_MAP_TARGET, k, inputs.target_mmhg, flush=False)
        self._flush_status()
        if flush:
            self.flush()

    def send_heartbeat(self, tick: int, state: int, *, flush: bool = True) -> None:
        if state == STATE_FINISHED:
            self._flush_status()  # the last tick's status precedes the end of the run
        super().send_heartbeat(tick, state, flush=flush)


def test_a_sample_first_device_without_scheduling_params_drives_the_pi_on_the_estimator():
    duration_s, ts = 60.0, 0.1
    pair = PtyPair.open()
    clock = ManualClock()
    device = SampleFirstNoSchedDevice(open_port(pair.follower_path), clock=clock)
    done: dict = {}

    def serve() -> None:
        try:
            world = World("paper-tracking", 3, ts)
            done["result"] = run_device(device, world, clock, duration_s=duration_s)
        finally:
            device.close()

    config = lockstep_run_config("pi", "estimated")
    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    t0 = time.monotonic()
    try:
        summary, result = run_runtime(pair.leader_port(), config, {"controller": "pi"}, None)
    finally:
        thread.join(30)
        pair.close()
    wall_s = time.monotonic() - t0
    assert done["result"].ended == "completed" and done["result"].counters["retransmits"] == 0
    assert summary["ticks"] == round(duration_s / ts) and result.ticks_in_state["AUTO"] == 600
    assert summary["link_dropped"] == dict.fromkeys(summary["link_dropped"], 0)
    ref = simulate(World("paper-tracking", 3, ts), load_controller("pi", ts), duration_s,
                   schedule=make_schedule("estimated", ts))  # fmt: skip
    tr = result.trajectory
    sent = tr["command_ml_h"].astype(np.float32).astype(np.float64)
    np.testing.assert_array_equal(sent, ref.command_ml_h)
    # every pump status arrived after its sample and was still used for its own tick
    np.testing.assert_array_equal(tr["delivered_ml_h"], ref.delivered_ml_h)
    assert wall_s < 30.0  # no 0.5 s resend per tick (600 ticks would take 300 s)
