"""A trial patient under the drug library's dose limits (hil_sim/trials/trial.py ``dose_limits``): the
supervisor cuts the command as ``pressor run``'s does, reachability is judged at the limit, the
record says how long each limit cut; without limits the record keeps its bytes."""

from __future__ import annotations

from pathlib import Path

from pressor.hil_sim.scenarios.scenario import load_scenario
from pressor.hil_sim.trials.trial import run_patient
from pressor.runtime.core.dose_guard import DoseLimits


def test_the_hard_limit_caps_the_command_and_decides_reachability(short_scenario: Path):
    scenario = load_scenario(short_scenario)
    # patient 1000001 (k0 0.978) holds 76.8 mmHg at 120 ml/h; at 20 ml/h at most
    # k0·20·e^(−k1·20) < 0.978·20 = 19.6 mmHg, short of the 30 − 5 mmHg the scenario asks
    limits = DoseLimits(
        hard_max_ml_h=20.0, soft_max_ml_h=10.0, max_ml_per_hour=1000.0, concentration_ug_ml=100.0
    )
    free = run_patient(scenario, "pi", 1000001)
    capped = run_patient(scenario, "pi", 1000001, dose_limits=limits)
    assert "dose" not in free and free["reachable"] and free["max_rate_ml_h"] > 20.0
    assert capped["max_rate_ml_h"] <= 20.0
    assert not capped["reachable"]
    assert capped["max_delta_mmhg"] < 0.978 * 20.0
    dose = capped["dose"]
    assert (dose["concentration_ug_ml"], dose["weight_kg"]) == (100.0, None)
    assert (dose["hard_max_ml_h"], dose["max_ml_per_hour"]) == (20.0, 1000.0)
    assert dose["hard_limited_s"] > 0.0 and dose["hour_limited_s"] == 0.0


def test_the_hourly_limit_is_counted_in_seconds_of_cut_commands(short_scenario: Path):
    scenario = load_scenario(short_scenario)
    # 0.5 ml per hour is 1.8 ml/h for 1000 s: the PI's first commands reach it within seconds, and
    # from there every tick's command is cut (tapered toward what the hour still allows, so the
    # hour's allowance is never exceeded)
    limits = DoseLimits(
        hard_max_ml_h=120.0, soft_max_ml_h=60.0, max_ml_per_hour=0.5, concentration_ug_ml=100.0
    )
    rec = run_patient(scenario, "pi", 1000001, dose_limits=limits)
    assert 0.1 < rec["drug_total_ml"] <= 0.5
    assert rec["dose"]["hour_limited_s"] > 250.0  # of the 300 s run
