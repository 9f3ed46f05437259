"""The bolus ceiling of the time in the band (research/bolus_ceiling.py)."""

from __future__ import annotations

import numpy as np

from pressor.api import simulate
from pressor.hil_sim.patients.sensitivity import with_sensitivity
from research.bolus_ceiling import SCENARIO, ceiling, stopped_at

BOLUS_S = 2100.0  # paper-disturbance's bolus


def test_the_replay_is_the_runs_patient_and_stopping_the_pump_never_raises_map():
    run = simulate(None, SCENARIO, 3_000_000, patient_model="norepinephrine")
    model = with_sensitivity("norepinephrine", 1.0)
    replay = stopped_at(run, model, BOLUS_S)
    t = np.asarray(run.trajectory.t_s)
    true_map = np.asarray(run.trajectory.map_true_mmhg)
    before = t < BOLUS_S
    assert np.array_equal(replay[before], true_map[before])
    assert np.all(replay[~before] <= true_map[~before] + 1e-9)
    c = ceiling(run, model, BOLUS_S)
    assert c is not None and c.replay_error_mmhg == 0.0
    assert c.in_band_pct <= c.ceiling_pct <= 100.0


def test_a_patient_not_yet_in_the_band_when_the_bolus_comes_has_no_ceiling():
    run = simulate(None, SCENARIO, 3_000_000, patient_model="norepinephrine", duration_s=120.0)
    # a +20 mmHg step from t = 0 is not within 5 mmHg after 60 s (the cautious start's doses)
    assert ceiling(run, with_sensitivity("norepinephrine", 1.0), 60.0) is None
