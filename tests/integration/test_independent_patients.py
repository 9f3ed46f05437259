"""The independent patient benchmark (benchmarks/independent_patients.py): its patient model against
hand-computed values, and one real ``pressor run`` with the PI through the protocol device."""

from __future__ import annotations

import math
from dataclasses import asdict, replace
from pathlib import Path
from types import ModuleType

import pytest

from benchmarks.independent_patients import (
    DRUGS,
    Setup,
    controller_label,
    figure_lines,
    main,
    run_patient,
    summary_lines,
)
from pressor.hil_sim.patients.pkpd import (
    BOLUS_AT_S,
    HEMORRHAGE_AT_S,
    RANGES,
    IndependentPatient,
    PatientParams,
    draw_patient,
)

ROOT = Path(__file__).resolve().parents[2]

#: a hand-picked patient whose steady state is easy to compute by hand (see the test)
HAND = PatientParams(
    baseline_mmhg=55.0,
    delay_s=20.0,
    cl_l_min=2.5,
    v1_l=10.0,
    q_l_min=1.0,
    v2_l=150.0,
    effect_lag_s=60.0,
    emax_mmhg=41.0,
    ec50_ng_ml=20.0,
    hill=2.0,
    tolerance_tau_s=1200.0,
    tolerance_gain=0.25,
    hemorrhage_mmhg=10.0,
    hemorrhage_ramp_s=60.0,
    bolus_mmhg=8.0,
    bolus_rise_s=90.0,
    bolus_decay_s=600.0,
)


def test_long_infusion_settles_on_the_documented_steady_state_computed_by_hand() -> None:
    # 30 ml/h of 100 ug/ml: Css = 30*100/(60*2.5) = 20 ng/ml in every compartment, tolerance too;
    # EC50_eff = 20 + 0.25*20 = 25 ng/ml, (20/25)^2 = 0.64, rise = 41*0.64/1.64 = 16 mmHg.
    patient = IndependentPatient(HAND, 1.0, 100.0, disturbances=False)
    for _ in range(40 * 3600):  # 40 h: ~11 time constants of the slow peripheral creep (~3.5 h)
        patient.step(30.0)
    assert patient.map_mmhg == pytest.approx(71.0, abs=0.05)
    assert patient.steady_state_map_mmhg(30.0) == pytest.approx(71.0, abs=1e-9)
    assert patient.steady_state_rate_ml_h(71.0, 120.0) == pytest.approx(30.0, abs=1e-6)


def test_infusion_reaches_the_map_only_after_the_transport_delay() -> None:
    patient = IndependentPatient(HAND, 0.1, 100.0, disturbances=False)
    seen = []
    for _ in range(600):
        patient.step(60.0)
        seen.append(patient.map_mmhg)
    assert all(m == HAND.baseline_mmhg for m in seen[:199])  # 20 s = 200 periods in the line
    assert seen[-1] > HAND.baseline_mmhg + 0.01


def test_haemorrhage_stays_down_and_the_bolus_decays_with_its_time_constant() -> None:
    d = IndependentPatient(HAND, 0.1, 100.0).disturbance_mmhg
    assert d(HEMORRHAGE_AT_S) == 0.0
    assert d(HEMORRHAGE_AT_S + 30.0) == pytest.approx(-5.0)
    assert d(BOLUS_AT_S) == pytest.approx(-10.0)
    assert d(BOLUS_AT_S + 90.0) == pytest.approx(-2.0)
    assert d(BOLUS_AT_S + 90.0 + 600.0) == pytest.approx(-10.0 + 8.0 * math.exp(-1.0))
    assert IndependentPatient(HAND, 0.1, 100.0, disturbances=False).disturbance_mmhg(3000.0) == 0.0


def test_patient_draws_are_seeded_per_index_and_inside_the_documented_ranges() -> None:
    assert draw_patient(5, 3) == draw_patient(5, 3)
    assert draw_patient(5, 3) != draw_patient(5, 4) and draw_patient(5, 3) != draw_patient(6, 3)
    for i in range(20):
        for name, value in asdict(draw_patient(1, i)).items():
            lo, hi = RANGES[name]
            assert lo <= value <= hi, (name, value)


def test_summary_counts_patients_below_the_pi_and_takes_median_ratios_per_segment() -> None:
    def rec(iae: float, step: float | None, reachable: bool = True) -> dict[str, object]:
        events = [{"kind": "hemorrhage", "iae_mmhg_s": iae / 4}, {"kind": "bolus", "iae_mmhg_s": 1}]
        return {
            "iae_mmhg_s": iae,
            "step_iae_mmhg_s": step,
            "disturbances": events,
            "reachable": reachable,
        }

    results = {
        "pi": [rec(100.0, 10.0), rec(200.0, 20.0), rec(100.0, 30.0), rec(50.0, 1.0, False)],
        "lpv": [rec(50.0, 10.0), rec(300.0, None), rec(200.0, 90.0), rec(10.0, 1.0, False)],
    }
    assert summary_lines(results) == [
        "LPV IAE below PI's: 1 of 3 reachable",
        "median IAE ratio lpv/pi: 1.500 (step window 2.000, haemorrhage 1.500, bolus 1.000)",
    ]
    assert summary_lines({"lpv": results["lpv"]}) == ["no pi run: no IAE comparison"]


def test_figures_count_reachable_patients_and_one_never_in_the_band_counts_the_run() -> None:
    def rec(over: float, to_band_s: float | None, reachable: bool = True) -> dict[str, object]:
        return {
            "step_overshoot_pct": over,
            "time_to_band_s": to_band_s,
            "time_in_band_pct": None if to_band_s is None else 96.0,
            "longest_above_10_mmhg_s": 40.0 if over > 50 else 0.0,
            "stable": True,
            "reachable": reachable,
        }

    results = {"x": [rec(0.0, 60.0), rec(10.0, None), rec(80.0, 600.0, reachable=False)]}
    # reachable: overshoot 0 and 10 % (median 5, p90 9), to the band 1 min and the run's 60 min
    assert figure_lines(results, 3600.0) == [
        "x: 2 reachable; overshoot % median / p90 / max 5.0 / 9.0 / 10.0; > 30 s above +10 mmHg 0;"
        " to ±5 mmHg min median / p90 30.5 / 54.1; in ±5 after entry % median 96.0;"
        " flagged unstable 0"
    ]


def test_norepinephrine_runs_pressor_run_on_its_syringe_and_weight_and_the_patient_counts_it(
    dialect: ModuleType,
) -> None:
    ne = DRUGS["norepinephrine"]
    assert ne.run_flags() == [
        "--drug", "norepinephrine", "--concentration-ug-ml", "16", "--weight-kg", "70"
    ]  # fmt: skip
    # 16 ug/ml of norepinephrine is 160 ug/ml of phenylephrine to the patient model
    assert ne.patient_concentration_ug_ml == pytest.approx(160.0)
    params = replace(draw_patient(2026, 0, "one-compartment"), baseline_mmhg=60.0)
    rec = run_patient(dialect, params, "pi", Setup(duration_s=900.0, drug=ne), seed=1)
    assert rec["reachable"] and rec["disturbances"] == []
    assert abs(rec["final_map_mmhg"] - 70.0) <= 5.0


def test_controller_names_come_from_the_spec_or_the_module_folder() -> None:
    assert controller_label("smith:45") == ("smith:45", "smith:45")
    assert controller_label("/x/s30/lpv_map_controller.py") == (
        "s30",
        "/x/s30/lpv_map_controller.py",
    )
    assert controller_label("new=/x/y.py") == ("new", "/x/y.py")


def test_pi_through_pressor_run_brings_an_independent_patient_to_target(
    dialect: ModuleType,
) -> None:
    setup = Setup(duration_s=900.0, target_mmhg=70.0, noise_mmhg=0.3)
    params = replace(draw_patient(2026, 1), baseline_mmhg=55.0)
    rec = run_patient(dialect, params, "pi", setup, seed=1)
    assert rec["disturbances"] == []  # both events start after 900 s
    assert rec["stable"] and rec["reachable"]
    assert abs(rec["final_map_mmhg"] - 70.0) <= 5.0
    # the whole 15 mmHg step contributes at least the delay's worth of error before MAP moves
    assert rec["iae_mmhg_s"] > 15.0 * params.delay_s


@pytest.mark.slow  # a non-default schedule's finding, two 10 min runs over the link
def test_lpv_on_the_device_sent_step_fit_overshoots_far_less_than_on_its_own_estimate(
    dialect: ModuleType,
) -> None:
    # the device sends the patient's step-response fit and pressor run schedules on it; without
    # it the same patient is run on the online estimate, whose start-up overshoots (40 %)
    params = draw_patient(2026, 0)
    runs = {
        fit: run_patient(dialect, params, "lpv", Setup(duration_s=600.0, device_fit=fit), seed=1)
        for fit in (True, False)
    }
    assert runs[False]["step_overshoot_pct"] > 30.0
    assert runs[True]["step_overshoot_pct"] < 20.0
    assert runs[True]["iae_mmhg_s"] < 0.7 * runs[False]["iae_mmhg_s"]


def test_same_seed_prints_the_same_bytes_and_progress_goes_to_stderr(
    capsys: pytest.CaptureFixture[str],
) -> None:
    argv = ["--patients", "1", "--duration-s", "30", "--controller", "pi", "--controller", "smith"]
    outputs = []
    for _ in range(2):
        assert main(argv) == 0
        out, err = capsys.readouterr()
        outputs.append(out)
        assert err.count("wall)") == 2 and "[2/2] patient 0 smith" in err
    assert outputs[0] == outputs[1]
    assert "SMITH IAE below PI's: " in outputs[0] and "median IAE ratio smith/pi: " in outputs[0]
    assert "wall" not in outputs[0]
