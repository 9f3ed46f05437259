"""The one closed-loop core: a trial patient and a lockstep SIL run over a real pty agree tick for
tick - MAP, command, delivered rate and the supervisor's state and faults - through faults that
take the supervisor out of AUTO and back."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pressor.baselines.pi import PIController
from pressor.contracts.faults import parse_faults
from pressor.hil_sim.episode import simulate
from pressor.hil_sim.world import World
from pressor.link import LINK_LOCKSTEP, Hello, PtyPair, RuntimeSession
from pressor.runtime.core.closed_loop import CLEAN_LINK, ClosedLoopCore, LinkHealth
from pressor.runtime.core.supervisor import Supervisor
from pressor.runtime.core.supervisor_config import (
    Fault,
    State,
    SupervisorConfig,
    supervisor_config_for,
)
from pressor.runtime.shell.loop import Loop
from pressor.runtime.shell.trajectory import held_delivered_ml_h
from tests.support.sil_helpers import spawn_device

SCENARIO, SEED, DURATION_S, TS = "paper-tracking", 3, 120.0, 0.1
#: a flushed line (MAP out of range: HOLD, then re-entry) and an occlusion long enough to escalate
FAULTS = ("sensor-flush:30,4", "pump-occlusion:60,15")


@pytest.fixture(scope="module")
def sil_and_trial():
    pair = PtyPair.open()
    ep = RuntimeSession(pair.leader_port())
    args = ("--scenario", SCENARIO, "--patient-seed", str(SEED), "--duration", str(DURATION_S))
    proc = spawn_device(pair, *args, *(a for f in FAULTS for a in ("--fault", f)))
    try:
        peer = ep.handshake(Hello("pi", sample_period_s=TS, link_mode=LINK_LOCKSTEP), 30.0)
        pi = PIController(TS)
        loop = Loop(pi, Supervisor(supervisor_config_for(pi, peer.sensor_noise_mmhg)), ep)
        result = loop.run_lockstep(peer.n_ticks)
    finally:
        ep.close()
        proc.wait(timeout=30)
        pair.close_follower()
    world = World(SCENARIO, SEED, TS, faults=tuple(parse_faults(list(FAULTS))))
    return result, simulate(world, PIController(TS), DURATION_S)


def test_sil_over_a_pty_and_the_trial_give_the_same_trajectory_and_supervisor_states(
    sil_and_trial,
):
    result, ref = sil_and_trial
    sil = result.trajectory
    n = ref.t_s.size
    assert result.ended == "completed" and list(sil["tick"]) == list(range(n))
    np.testing.assert_array_equal(sil["map_mmhg"], ref.map_mmhg)
    sent = sil["command_ml_h"].astype(np.float32).astype(np.float64)  # float32 on the wire
    np.testing.assert_array_equal(sent, ref.command_ml_h)
    np.testing.assert_array_equal(sil["delivered_ml_h"], ref.delivered_ml_h)  # the last one too
    np.testing.assert_array_equal(sil["state"], ref.state)
    np.testing.assert_array_equal(sil["faults"], ref.faults)
    # the faults really exercised the supervisor, in both
    visited = set(ref.state.tolist())
    assert {State.AUTO, State.HOLD, State.FAILSAFE, State.RECOVERING} <= visited
    assert np.any(ref.faults & Fault.MAP_RANGE) and np.any(ref.faults & Fault.PUMP_ALARM)
    assert ref.state[-1] == State.AUTO  # and handed control back


def test_occluded_pump_delivers_less_than_commanded_and_the_delivered_rate_shows_it(
    sil_and_trial,
):
    result, ref = sil_and_trial
    sil = result.trajectory
    occluded = (ref.t_s >= 60.0) & (ref.t_s < 75.0)
    assert np.all(sil["delivered_ml_h"][occluded] == 0.0)
    assert np.all(sil["command_ml_h"][occluded] > 0.0)
    # over the run the pump delivered what the trial's mean-rate integral says, within float32
    np.testing.assert_allclose(
        held_delivered_ml_h(sil["delivered_ml_h"]).sum(), ref.rate_ml_h.sum(), rtol=1e-6
    )


def test_held_delivered_rate_fills_missing_statuses_with_the_previous_report():
    nan = math.nan
    got = held_delivered_ml_h(np.array([nan, 2.0, nan, nan, 5.0, nan]))
    np.testing.assert_array_equal(got, [0.0, 2.0, 2.0, 2.0, 5.0, 5.0])


class CountingController(PIController):
    """PI that counts its steps."""

    steps = 0

    def step(self, *args: float) -> float:
        self.steps += 1
        return super().step(*args)


def test_core_does_not_step_the_controller_while_the_supervisor_holds():
    world = World(SCENARIO, SEED, TS, faults=tuple(parse_faults(["sensor-nan:1,1"])))
    pi = CountingController(TS)
    core = ClosedLoopCore(pi, Supervisor(supervisor_config_for(pi, 0.0)))
    records = []
    for _ in range(30):
        obs = world.observe()
        records.append(core.step(obs, obs.sim_time_s, None, CLEAN_LINK))
        world.apply_command(records[-1].command_ml_h)
        world.advance()
    held = [r for r in records if not r.supervisor.run_controller]
    assert held and all(math.isnan(r.controller_ml_h) for r in held)
    assert pi.steps == sum(r.supervisor.run_controller for r in records)
    assert records[11].supervisor.state == State.HOLD
    assert records[11].command_ml_h == records[9].command_ml_h  # held through the fault


def test_core_passes_link_health_to_the_watchdogs():
    pi = PIController(TS)
    core = ClosedLoopCore(pi, Supervisor(supervisor_config_for(pi, 0.0)))
    obs = World(SCENARIO, SEED, TS).observe()
    rec = core.step(obs, 0.0, None, LinkHealth(sample_age_s=0.0, link_silence_s=2.0, link_errors=1))
    assert rec.supervisor.faults & Fault.LINK_LOSS and rec.supervisor.faults & Fault.LINK_ERRORS


def test_core_refuses_a_supervisor_at_another_period():
    with pytest.raises(ValueError, match="sample_period_s"):
        ClosedLoopCore(PIController(TS), Supervisor(SupervisorConfig(sample_period_s=0.2)))
