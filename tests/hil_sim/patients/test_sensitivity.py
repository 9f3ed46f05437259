"""Drug sensitivity scaled by a factor (hil_sim/patients/sensitivity.py): the wrapped patients'
responses against closed forms computed here, the factor's range, ``pressor trial --sensitivity``
and the API's ``sensitivity=``; a factor of 1 is the unwrapped model byte for byte."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from pressor import api
from pressor.hil_sim.cli import main
from pressor.hil_sim.patients.patient import Patient, PatientParams
from pressor.hil_sim.patients.patient_model import (
    PatientModelError,
    check_model_for_scenario,
    load_patient_model,
)
from pressor.hil_sim.patients.sensitivity import (
    SensitivityScaled,
    check_factor,
    split_spec,
    with_sensitivity,
)
from tests.support.patient_plugin import FirstOrderPatient

#: the paper model's patient of tests/hil_sim/patients/test_patient_model.py: steady state
#: k0·i·e^(−k1·i)
PAPER = PatientParams(
    a_k=500.0,
    k0=0.5,
    k1=0.005,
    b_T=2e-4,
    a_tau1=10.0,
    a_tau2=10.0,
    b_tau1=100.0,
    baseline_mmhg=50.0,
)


def test_a_first_order_patient_at_4x_responds_as_to_four_times_the_rate_with_k_scaled_only():
    p = SensitivityScaled(FirstOrderPatient(0.5, 100.0, 20.0, 50.0, 0.1), 4.0)
    for _ in range(1200):  # 20 s of delay, then one lag (100 s) of 10 ml/h
        p.step(10.0)
    hand = 0.5 * 4.0 * 10.0 * (1.0 - math.exp(-1.0))  # 12.642 mmHg
    assert p.delta_map_mmhg == pytest.approx(hand, rel=1e-9)
    assert p.map_mmhg == pytest.approx(50.0 + hand, rel=1e-12)
    assert p.baseline_mmhg == 50.0
    assert (p.K, p.T_s) == (2.0, 100.0)
    assert p.tau_s == pytest.approx(20.0)
    assert p.max_delta_map_mmhg(120.0) == pytest.approx(0.5 * 4.0 * 120.0)
    assert p.coefficients() == {
        "K": 0.5,
        "T_s": 100.0,
        "tau_s": pytest.approx(20.0),
        "baseline_mmhg": 50.0,
        "sensitivity_factor": 4.0,
    }


def test_the_paper_model_at_half_sensitivity_settles_on_its_curve_at_half_the_rate():
    p = SensitivityScaled(Patient(PAPER, 1.0), 0.5)
    for _ in range(4 * 3600):  # 4 h at 40 ml/h: the drug state sees 20 ml/h
        p.step(40.0)
    # input scaling k0·(f·i)·e^(−k1·f·i), not output scaling f·k0·i·e^(−k1·i) (8.19 mmHg)
    assert p.delta_map_mmhg == pytest.approx(0.5 * 20.0 * math.exp(-0.005 * 20.0), abs=1e-6)
    assert p.K == pytest.approx(0.5 * 0.5 * math.exp(-0.005 * 20.0), rel=1e-6)


def test_the_paper_models_reachable_delta_at_10x_is_its_curves_peak_not_ten_times_its_own():
    p = SensitivityScaled(Patient(PAPER, 0.1), 10.0)
    # 10 × 120 ml/h passes the curve's peak at 1/k1 = 200 ml/h: k0·200·e^(−1) = 36.79 mmHg
    assert p.max_delta_map_mmhg(120.0) == pytest.approx(0.5 * 200.0 * math.exp(-1.0))
    low = SensitivityScaled(Patient(PAPER, 0.1), 0.1)
    assert low.max_delta_map_mmhg(120.0) == pytest.approx(0.5 * 12.0 * math.exp(-0.06))


def test_a_factor_of_one_steps_the_paper_patient_tick_for_tick_as_the_unwrapped_one():
    plain = Patient.from_seed(3, 0.1)
    wrapped = load_patient_model("paper@sensitivity=1").from_seed(3, 0.1)
    for k in range(6000):
        rate = 0.0 if k < 100 else 30.0 + 20.0 * math.sin(k / 300.0)
        plain.step(rate)
        wrapped.step(rate)
        assert (wrapped.map_mmhg, wrapped.K, wrapped.T_s, wrapped.tau_s) == (
            plain.map_mmhg,
            plain.K,
            plain.T_s,
            plain.tau_s,
        )


def test_the_spec_form_loads_any_model_scaled_with_the_factor_and_its_unit():
    model = load_patient_model("tests.support.patient_plugin:FirstOrderPatient@sensitivity=2.5")
    inner = FirstOrderPatient.from_seed(11, 0.1)
    p = model.from_seed(11, 0.1)
    assert p.K == 2.5 * inner.K and p.T_s == inner.T_s and p.tau_s == inner.tau_s
    assert p.coefficients()["sensitivity_factor"] == 2.5
    assert model.coefficient_units["sensitivity_factor"] == "1"
    assert model.coefficient_units["K"] == "mmHg/(ml/h)"
    assert split_spec("pkpd@sensitivity=0.2") == ("pkpd", 0.2)
    assert split_spec("pkpd") == ("pkpd", None)


def test_the_range_ends_are_accepted_and_anything_outside_is_refused_naming_value_and_range():
    assert (check_factor(0.05), check_factor(20)) == (0.05, 20.0)
    for bad in (0.049, 20.01, 0.0, -1.0, math.nan, math.inf, True, "2"):
        with pytest.raises(PatientModelError, match=r"must be a finite number in \[0.05, 20\]"):
            check_factor(bad)
    with pytest.raises(PatientModelError, match=r"sensitivity = 'abc'.*\[0.05, 20\]"):
        load_patient_model("paper@sensitivity=abc")
    with pytest.raises(PatientModelError, match=r"sensitivity = 25.0.*\[0.05, 20\]"):
        load_patient_model("paper@sensitivity=25")


def test_with_sensitivity_leaves_one_unwrapped_and_refuses_a_second_factor():
    assert with_sensitivity("paper", 1.0) == "paper"
    assert with_sensitivity("paper", 10) == "paper@sensitivity=10.0"
    assert with_sensitivity("paper", 0.1) == "paper@sensitivity=0.1"
    with pytest.raises(PatientModelError, match="give the factor once"):
        with_sensitivity("paper@sensitivity=2.0", 3.0)


def test_a_frozen_scenario_refuses_a_scaled_paper_model():
    with pytest.raises(PatientModelError, match="without a sensitivity factor"):
        check_model_for_scenario("paper@sensitivity=2.0", "nominal-step", True)


def _trial(tmp: Path, scenario: Path, name: str, *extra: str) -> Path:
    out = tmp / name
    argv = ["--controller", "pi", "--patients", "2", "--seed", "1", "--scenario", str(scenario)]
    assert main("trial", [*argv, *extra, "--out", str(out)]) == 0
    return out


def test_trial_at_sensitivity_one_writes_the_bytes_of_a_trial_without_the_option(
    tmp_path: Path, short_scenario: Path
):
    plain = _trial(tmp_path, short_scenario, "plain")
    one = _trial(tmp_path, short_scenario, "one", "--sensitivity", "1")
    for f in ("patients.json", "patients.csv", "summary.json"):
        assert (one / f).read_bytes() == (plain / f).read_bytes(), f


def test_trial_at_sensitivity_10_records_k_ten_times_k0_and_names_the_factor(
    tmp_path: Path, short_scenario: Path
):
    out = _trial(tmp_path, short_scenario, "x10", "--sensitivity", "10")
    records = json.loads((out / "patients.json").read_text())
    for r in records:
        assert r["patient_model"] == "paper@sensitivity=10.0"
        assert r["coefficients"]["sensitivity_factor"] == 10.0
        k0 = r["coefficients"]["k0"]  # K starts at k0 and only falls: its max is 10·k0
        assert r["schedule_range"]["K_mmhg_per_ml_h"][1] == pytest.approx(10.0 * k0, rel=1e-6)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["patient_model"] == "paper@sensitivity=10.0"
    header = (out / "patients.csv").read_text().splitlines()[0]
    assert "sensitivity_factor (1)" in header


@pytest.mark.parametrize("value", ["25", "0.01", "nan"])
def test_trial_refuses_a_sensitivity_outside_its_range_with_exit_2(
    tmp_path: Path, short_scenario: Path, capsys, value: str
):
    argv = ["--patients", "1", "--scenario", str(short_scenario), "--sensitivity", value]
    assert main("trial", [*argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"--sensitivity = {float(value)}: must be a finite number in [0.05, 20]" in err
    assert not (tmp_path / "o").exists()


def test_the_api_scales_the_patient_and_refuses_a_factor_outside_the_range(short_scenario: Path):
    run = api.simulate("pi", short_scenario, patient_seed=4, sensitivity=2.0)
    assert run.record["patient_model"] == "paper@sensitivity=2.0"
    k0 = run.record["coefficients"]["k0"]
    assert float(run.trajectory.K[0]) == pytest.approx(2.0 * k0, rel=1e-6)
    with pytest.raises(ValueError, match=r"sensitivity = 0.01.*\[0.05, 20\]"):
        api.trial("pi", short_scenario, n_patients=1, sensitivity=0.01)
