"""What a dose limit can hold (pressor.hil_sim.reach): capacity runs against hand-computed answers."""

from __future__ import annotations

import numpy as np
import pytest

from pressor.hil_sim import reach
from pressor.hil_sim.world import World

#: a pkpd patient at 0.5x whose steady state at 60 ml/h lifts MAP 35.1 mmHg (the scenario asks
#: 30 at worst), but whose hour at 60 ml/h does not hold it: slow peripheral filling, tolerance
PKPD_SEED = 2026000249


def test_capacity_of_a_frozen_first_order_patient_is_its_step_response() -> None:
    world = World("nominal-step", 0, 0.1)  # K 0.55 mmHg/(ml/h), T 150 s, tau 40 s
    t, rise = reach.capacity_mmhg(world, 30.0)
    hand = np.where(t > 40.0, 0.55 * 30.0 * (1.0 - np.exp(-(t - 40.0) / 150.0)), 0.0)
    assert t[0] == 0.0 and t[-1] == world.scenario.duration_s
    np.testing.assert_allclose(rise, hand, atol=1e-9)


def test_a_frozen_patient_is_held_only_within_the_band_of_its_steady_state() -> None:
    world = World("nominal-step", 0, 0.1)  # noise-free: band 2 % of the 20 mmHg step, 0.4 mmHg
    assert world.band_mmhg() == pytest.approx(0.4)
    short_of = 0.3  # mmHg: inside the band
    assert reach.holds(world, (20.0 - short_of) / 0.55)
    # 1 mmHg short at steady state, reached only asymptotically: 20 - 0.55 r (1 - e^(-1160/150))
    rate = 19.0 / 0.55
    hand = 20.0 - 0.55 * rate * (1.0 - np.exp(-(1200.0 - 40.0) / 150.0))
    assert not reach.holds(world, rate)
    assert reach.hold_shortfall_mmhg(world, rate) == pytest.approx(hand, abs=1e-6)


def test_best_rate_of_the_paper_model_is_the_peak_of_its_falling_gain() -> None:
    # k0·(f·i)·e^(-k1·f·i) peaks at i = 1 / (f·k1): below the limit at 10x
    world = World("paper-disturbance", 7, 0.1, patient_model="paper@sensitivity=10")
    k1 = world.patient.coefficients()["k1"]
    assert reach.best_rate_ml_h(world.patient, 60.0) == pytest.approx(1.0 / (10.0 * k1), rel=1e-6)
    assert reach.best_rate_ml_h(world.patient, 10.0) == 10.0


def test_a_pkpd_patient_the_steady_state_reaches_but_the_hour_does_not_hold_is_not_held() -> None:
    world = World("paper-disturbance", PKPD_SEED, 0.1, patient_model="pkpd@sensitivity=0.5")
    assert world.patient.max_delta_map_mmhg(60.0) > world.required_delta_mmhg() + 5.0
    assert world.reachable(60.0)
    assert reach.best_rate_ml_h(world.patient, 60.0) == 60.0  # the Emax effect rises with the rate
    assert not reach.holds(world, 60.0)
    assert reach.hold_shortfall_mmhg(world, 60.0) > world.band_mmhg()
    # the same patient ten times as sensitive is held
    sensitive = World("paper-disturbance", PKPD_SEED, 0.1, patient_model="pkpd@sensitivity=10")
    assert reach.holds(sensitive, 60.0)


def test_capacity_runs_on_a_fresh_patient_and_leaves_the_worlds_own_untouched() -> None:
    world = World("paper-disturbance", PKPD_SEED, 0.1, patient_model="pkpd")
    before = world.patient.delta_map_mmhg
    reach.capacity_mmhg(world, 60.0)
    assert world.patient.delta_map_mmhg == before == 0.0
    assert world.fresh_patient(1.0) is not world.patient
