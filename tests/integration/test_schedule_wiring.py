"""The scheduling source in the closed-loop core: what it is fed, what the supervisor and the
controller see, a device that sends no scheduling parameters, trial and SIL on the estimator."""

from __future__ import annotations

import contextlib
import json
import math
import threading

import numpy as np
import pytest

from pressor.baselines.pi import PIController
from pressor.contracts.metrics import step_metrics
from pressor.hil_sim.devices.device import run_device
from pressor.hil_sim.episode import simulate
from pressor.hil_sim.scenarios.scenario import load_scenario
from pressor.hil_sim.trials.trial import run_patient
from pressor.hil_sim.world import World
from pressor.link import DeviceSession, ManualClock, PtyPair, TickInputs, open_port
from pressor.link.dialect import pressor as mavlink
from pressor.runtime.core.closed_loop import CLEAN_LINK, ClosedLoopCore, LinkHealth
from pressor.runtime.core.scheduling import Schedule, ScheduleInput
from pressor.runtime.core.supervisor import Supervisor
from pressor.runtime.core.supervisor_config import Fault, State, supervisor_config_for
from pressor.runtime.estimation.settings import DESIGN_BOX, NOMINAL_PLANT
from pressor.runtime.estimation.sources import make_schedule
from pressor.runtime.inputs.controller_loader import load_controller
from pressor.runtime.session import run_runtime
from tests.support.sil_helpers import (
    assert_recording_equals_simulation,
    lockstep_run_config,
    pressor,
    rrd_columns,
)

SCENARIO, SEED, TS = "paper-tracking", 3, 0.1


class SpySchedule:
    """An "estimator" remembering what it was fed and returning fixed values."""

    source = "estimated"

    def __init__(self, values: tuple[float, float, float], healthy: bool) -> None:
        self.fed: list[tuple[float, int, float]] = []
        self.schedule = Schedule(*values, "estimated", True, healthy, not healthy,
                                 "ok" if healthy else "diverged")  # fmt: skip

    def update(self, inputs: ScheduleInput) -> Schedule:
        self.fed.append((inputs.map_mmhg, inputs.quality, inputs.delivered_ml_h))
        return self.schedule


class SpyController(PIController):
    """PI remembering the K, T, τ it was stepped with."""

    def __init__(self, ts: float) -> None:
        super().__init__(ts)
        self.seen: list[tuple[float, float, float]] = []

    def step(self, map_mmhg, target_mmhg, K, T, tau) -> float:
        self.seen.append((K, T, tau))
        return super().step(map_mmhg, target_mmhg, K, T, tau)


def test_core_feeds_the_source_the_latest_delivered_rate_and_steps_the_controller_on_its_values():
    world = World(SCENARIO, SEED, TS)
    ctl = SpyController(TS)
    box = ((0.25, 1.0), (100.0, 200.0), (10.0, 45.0))
    sup = Supervisor(supervisor_config_for(ctl, 0.0, sched_box=box, sched_required=True))
    spy = SpySchedule((0.5, 150.0, 30.0), healthy=False)
    core = ClosedLoopCore(ctl, sup, spy)
    status, delivered = None, []
    for k in range(5):
        obs = world.observe()
        rec = core.step(obs, obs.sim_time_s, status if k != 3 else None, CLEAN_LINK)
        world.apply_command(rec.command_ml_h)
        status = world.advance()
        delivered.append(status.delivered_ml_h)
    assert spy.fed[0][2] == 0.0  # no pump status yet: nothing flowing
    assert [f[2] for f in spy.fed[1:]] == [delivered[0], delivered[1], delivered[1], delivered[3]]
    assert ctl.seen == [(0.5, 150.0, 30.0)] * 5  # not the world's truth
    # the supervisor saw the same values: the unhealthy estimator is an advisory fault only
    assert rec.supervisor.faults == Fault.ESTIMATOR_FALLBACK
    assert rec.supervisor.state == State.AUTO and rec.supervisor.alarm
    assert rec.schedule.K == 0.5


class NoSchedDevice(DeviceSession):
    """A device that never sends SCHEDULING_PARAMS (a real monitor and pump know no K, T, τ)."""

    def send_tick(self, inputs: TickInputs, *, flush: bool = True) -> None:
        k = inputs.tick
        send = self.send_fields
        send(mavlink.MAVLINK_MSG_ID_MAP_TARGET, k, inputs.target_mmhg, flush=False)
        send(mavlink.MAVLINK_MSG_ID_MAP_SAMPLE, inputs.sim_time_s, k, inputs.map_mmhg,
             inputs.quality, flush=flush)  # fmt: skip


@pytest.mark.parametrize("controller", ["lpv", "pi"])
def test_a_device_that_never_sends_scheduling_params_completes_a_run_with_the_estimator(
    controller,
):
    duration_s = 120.0
    pair = PtyPair.open()
    clock = ManualClock()
    device = NoSchedDevice(open_port(pair.follower_path), clock=clock)
    world = World(SCENARIO, SEED, TS)
    done: dict = {}

    def serve() -> None:
        try:
            done["result"] = run_device(device, world, clock, duration_s=duration_s)
        finally:
            device.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        summary, result = run_runtime(
            pair.leader_port(),
            lockstep_run_config(controller, "estimated"),
            {"controller": controller},
            None,
        )
    finally:
        thread.join(30)
        pair.close()
    assert done["result"].ended == "completed"
    assert result.ended in ("device finished", "completed")
    assert summary["ticks"] == round(duration_s / TS)
    assert summary["schedule"] == "estimated"
    assert result.link["incomplete_sched"] == result.link["incomplete_target"] == 0
    assert result.ticks_in_state["AUTO"] == summary["ticks"]  # no SCHED_INVALID hold
    assert result.trajectory["command_ml_h"].max() > 1.0  # the loop infused
    ref = simulate(World(SCENARIO, SEED, TS), load_controller(controller, TS), duration_s,
                   schedule=make_schedule("estimated", TS))  # fmt: skip
    sent = result.trajectory["command_ml_h"].astype(np.float32).astype(np.float64)
    np.testing.assert_array_equal(sent, ref.command_ml_h)


@pytest.fixture(scope="module")
def estimated_sil(tmp_path_factory):
    d = tmp_path_factory.mktemp("est")
    rrd, summary = d / "est.rrd", d / "est.json"
    proc = pressor(
        "sil",
        *("--schedule", "estimated", "--scenario", SCENARIO, "--patient-seed", str(SEED)),
        *("--duration", "900", "--rrd", str(rrd), "--summary", str(summary)),
        cwd=d,
    )
    assert proc.returncode == 0, proc.stderr
    return rrd, json.loads(summary.read_text())


def test_lockstep_sil_and_trial_agree_tick_for_tick_on_the_estimator(estimated_sil):
    rrd, summary = estimated_sil
    assert summary["schedule"] == "estimated"
    ref = simulate(World(SCENARIO, SEED, TS), load_controller("lpv", TS), 900.0,
                   schedule=make_schedule("estimated", TS))  # fmt: skip
    assert_recording_equals_simulation(rrd, ref)
    cols = rrd_columns(rrd)
    n = ref.t_s.size
    K_hat = np.array([cols["/schedule/estimated/K"][k] for k in range(n)])
    np.testing.assert_array_equal(K_hat, ref.sched_K)
    assert np.any(K_hat != NOMINAL_PLANT[0])  # the estimator left its prior
    lo, hi, T_lo, T_hi = (
        np.array([cols[f"/schedule/estimated/{name}"][k] for k in range(n)])
        for name in ("K_lo", "K_hi", "T_lo_s", "T_hi_s")
    )
    # the scheduled K sits on the low-gain side of the estimate, inside its band, except where the
    # estimate's T fell below the design box: then it moved along K/T onto the box's T edge
    below_box = (T_lo + T_hi) / 2.0 < DESIGN_BOX[1][0]
    assert np.all(lo < K_hat) and np.all(K_hat[~below_box] < hi[~below_box])
    assert np.all(ref.sched_T_s[below_box] == DESIGN_BOX[1][0])
    # the device's truth is still recorded beside the estimate
    K_dev = np.array([cols["/schedule/K"][k] for k in range(n)])
    np.testing.assert_array_equal(K_dev, ref.K.astype(np.float32))


def test_trial_record_carries_estimation_errors_only_off_the_oracle():
    scenario = load_scenario(SCENARIO)
    oracle = run_patient(scenario, "pi", SEED, TS, "oracle")
    nominal = run_patient(scenario, "pi", SEED, TS, "nominal")
    assert "estimation" not in oracle
    est = nominal["estimation"]
    assert set(est) == {"K_rel_err_pct", "T_rel_err_pct", "tau_abs_err_s"}
    # the nominal constants against this patient's truth over the second half
    world = World(SCENARIO, SEED, TS)
    ref = simulate(world, PIController(TS))
    half = ref.t_s.size // 2
    expected = np.median(np.abs(NOMINAL_PLANT[0] - ref.K[half:]) / ref.K[half:] * 100.0)
    assert est["K_rel_err_pct"] == pytest.approx(expected)
    assert est["K_rel_err_pct"] > 0.0
    # the PI ignores K, T, τ: same metrics whatever the source
    assert nominal["iae_mmhg_s"] == oracle["iae_mmhg_s"]


def test_schedule_option_defaults_estimated_for_run_and_oracle_for_sil_and_trial(tmp_path):
    from pressor.runtime.cli import _run_parser
    from pressor.sil import sil_parser

    assert _run_parser().parse_args(["--port", "x"]).schedule == "estimated"
    assert sil_parser().parse_args([]).schedule == "oracle"
    for cmd in ("run", "sil", "trial"):
        out = " ".join(pressor(cmd, "--help", cwd=tmp_path).stdout.split())  # unwrapped
        assert "--schedule {oracle,estimated,nominal,validated,cautious}" in out
        assert ("default estimated" if cmd == "run" else "default oracle") in out
    bad = pressor("trial", "--schedule", "guess", "--out", str(tmp_path), cwd=tmp_path)
    assert bad.returncode == 2 and "--schedule" in bad.stderr


def test_estimator_faults_are_documented_with_their_bounds(tmp_path):
    out = pressor("faults", cwd=tmp_path).stdout
    assert "ESTIMATOR_FALLBACK" in out and "falls back to the prior" in out
    assert "ESTIMATE_OUT_OF_BOX" in out and "60 s" in out


def test_an_estimate_outside_the_box_raises_the_advisory_after_the_documented_time():
    ctl = PIController(TS)
    box = ((0.25, 1.0), (100.0, 200.0), (10.0, 45.0))
    sup = Supervisor(supervisor_config_for(ctl, 0.0, sched_box=box, sched_required=True))
    core = ClosedLoopCore(ctl, sup, SpySchedule((0.1, 150.0, 30.0), healthy=True))
    world = World(SCENARIO, SEED, TS)
    flagged = []
    for _ in range(round(61.0 / TS)):
        obs = world.observe()
        rec = core.step(obs, obs.sim_time_s, None, CLEAN_LINK)
        world.apply_command(rec.command_ml_h)
        world.advance()
        flagged.append(bool(rec.supervisor.faults & Fault.ESTIMATE_OUT_OF_BOX))
        assert rec.supervisor.state == State.AUTO  # advisory: the loop keeps running
    first = flagged.index(True)
    assert first == round(60.0 / TS) and all(flagged[first:])
    assert sup.detections["ESTIMATE_OUT_OF_BOX"] == 1
    assert not math.isnan(rec.controller_ml_h)


def test_a_repeated_sample_of_a_silent_link_is_held_for_the_source_until_the_age_limit():
    ctl = PIController(TS)
    spy = SpySchedule((0.5, 150.0, 30.0), healthy=True)
    core = ClosedLoopCore(ctl, Supervisor(supervisor_config_for(ctl, 0.0)), spy)
    obs = World(SCENARIO, SEED, TS).observe()
    core.step(obs, 0.0, None, CLEAN_LINK)
    core.step(obs, 0.1, None, LinkHealth(sample_age_s=0.1, link_silence_s=0.1, link_errors=0))
    core.step(obs, 3.2, None, LinkHealth(sample_age_s=3.2, link_silence_s=0.1, link_errors=0))
    # sample-and-hold (docs/PROTOCOL.md): the held value within the 3 s limit, NaN past it
    assert spy.fed[0][0] == obs.map_mmhg and spy.fed[1][0] == obs.map_mmhg
    assert math.isnan(spy.fed[2][0])


def test_the_summarys_settling_band_is_the_callers_not_the_devices_noise_announcement():
    duration_s = 300.0
    pair = PtyPair.open()
    clock = ManualClock()
    device = DeviceSession(open_port(pair.follower_path), clock=clock)
    world = World("bedside-monitor", SEED, TS)  # announces 0.5 mmHg of noise in its hello
    thread = threading.Thread(
        target=lambda: (run_device(device, world, clock, duration_s=duration_s), device.close()),
        daemon=True,
    )
    thread.start()
    try:
        summary, result = run_runtime(
            pair.leader_port(), lockstep_run_config("lpv", "oracle"), {"controller": "lpv"}, None,
            noisy_band=False,
        )  # fmt: skip
    finally:
        thread.join(30)
        pair.close()
    assert summary["sensor_noise_mmhg"] == 0.5
    tr = result.trajectory
    t, y, r = tr["sim_time_s"], tr["map_mmhg"], tr["target_mmhg"]
    two_pct = step_metrics(t, y, r, 0.0, float(r[0] - y[0]), noisy=False)["settling_time_s"]
    five = step_metrics(t, y, r, 0.0, float(r[0] - y[0]), noisy=True)["settling_time_s"]
    # integer readings never stay within 2 % of the step (0.4 mmHg); they settle within 5 mmHg
    assert summary["metrics"]["settling_time_s"] == two_pct and two_pct != five
    assert five is not None


def test_a_device_announcing_an_impossible_noise_is_refused_with_one_line():
    from pressor.link import LINK_LOCKSTEP, Hello, LinkError
    from pressor.link.counters import HelloRefused

    pair = PtyPair.open()
    device = DeviceSession(open_port(pair.follower_path), clock=ManualClock())
    hello = Hello("noisy", 1, TS, math.nan, 10, LINK_LOCKSTEP)

    def announce() -> None:
        with contextlib.suppress(LinkError):  # the runtime refuses and closes the link
            device.handshake(hello, timeout_s=10.0)

    thread = threading.Thread(target=announce, daemon=True)
    thread.start()
    try:
        with pytest.raises(HelloRefused, match="sensor_noise_mmhg nan: allowed") as info:
            run_runtime(
                pair.leader_port(), lockstep_run_config("pi", "oracle"), {"controller": "pi"}, None
            )
        assert "\n" not in str(info.value)
        assert info.value.reason == 6  # PRESSOR_REFUSAL_REASON sensor noise (docs/PROTOCOL.md)
    finally:
        thread.join(15)
        device.close()
        pair.close()
