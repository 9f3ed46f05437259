"""Patient models as plugins: every named model's steady state and step response against values
computed by hand here (closed forms, not the code under test), their seeded draws, the
``--patient-model`` path through ``pressor trial`` and its errors."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, replace
from pathlib import Path

import pytest

from pressor.hil_sim.cli import main
from pressor.hil_sim.patients.patient import T_MIN_S, TAU_MIN_S, Patient, PatientParams
from pressor.hil_sim.patients.patient_model import PATIENT_MODELS, PatientModel, load_patient_model
from pressor.hil_sim.patients.phenylephrine import (
    RANGES,
    Phenylephrine2C,
    PhenylephrineParams,
    draw_params,
)
from pressor.hil_sim.patients.pkpd import PatientParams as PkpdParams
from pressor.hil_sim.patients.pkpd import PkpdPatient
from pressor.hil_sim.world import World

PLUGIN = "tests.support.patient_plugin:FirstOrderPatient"


def run(model: PatientModel, rate_ml_h: float, seconds: float, step_s: float) -> None:
    for _ in range(round(seconds / step_s)):
        model.step(rate_ml_h)


def two_compartment_step(
    t_min: float, in_ug_min: float, v1_l: float, k10: float, k12: float, k21: float, ke0: float
) -> tuple[float, float]:
    """Plasma and effect-site levels (ng/ml) ``t_min`` after a constant infusion starts, in closed
    form: C1 = u/V1·Σ cᵢ(1 − e^(−λᵢt))/λᵢ over the two modes, Ce its first-order lag (rates 1/min)."""
    s = k10 + k12 + k21
    root = math.sqrt(s * s - 4.0 * k10 * k21)
    modes = ((s + root) / 2.0, (s - root) / 2.0)
    alpha, beta = modes
    weights = ((alpha - k21) / (alpha - beta), (k21 - beta) / (alpha - beta))
    c1 = ce = 0.0
    for lam, w in zip(modes, weights, strict=True):
        c1 += w * (1.0 - math.exp(-lam * t_min)) / lam
        ce += (
            w
            * ke0
            / (ke0 - lam)
            * ((1.0 - math.exp(-lam * t_min)) / lam - (1.0 - math.exp(-ke0 * t_min)) / ke0)
        )
    return in_ug_min / v1_l * c1, in_ug_min / v1_l * ce


# -- paper ----------------------------------------------------------------------------------------
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


def test_paper_model_settles_on_k0_i_exp_minus_k1_i_and_reports_it_as_reachable() -> None:
    patient = Patient(PAPER, 1.0)
    run(patient, 40.0, 4 * 3600.0, 1.0)  # 4 h: ~29 a_k, T and the τ filter long settled
    hand = 0.5 * 40.0 * math.exp(-0.005 * 40.0)  # 16.375 mmHg
    assert patient.delta_map_mmhg == pytest.approx(hand, abs=1e-6)
    assert patient.max_delta_map_mmhg(120.0) == pytest.approx(0.5 * 120.0 * math.exp(-0.6))
    assert patient.max_delta_map_mmhg(500.0) == pytest.approx(0.5 * 200.0 * math.exp(-1.0))


def test_paper_model_step_moves_k_and_t_as_their_closed_forms_and_map_only_after_tau_min() -> None:
    patient = Patient(PAPER, 0.5)
    seen = []
    for _ in range(round(600.0 / 0.5)):
        patient.step(60.0)
        seen.append(patient.delta_map_mmhg)
    k_inf = 0.5 * math.exp(-0.005 * 60.0)
    assert patient.K == pytest.approx(k_inf + (0.5 - k_inf) * math.exp(-600.0 / 500.0), rel=1e-12)
    assert patient.T_s == pytest.approx(T_MIN_S + 2e-4 * 60.0 * 600.0, rel=1e-12)  # 107.2 s
    assert all(x == 0.0 for x in seen[: round(TAU_MIN_S / 0.5)])  # nothing arrives before 10 s
    assert seen[-1] > 5.0


# -- pkpd -----------------------------------------------------------------------------------------
PKPD = PkpdParams(
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


def test_pkpd_model_settles_on_its_hand_computed_steady_state_without_disturbances() -> None:
    # 30 ml/h of 100 ug/ml: Css = 3000/(60*2.5) = 20 ng/ml everywhere, tolerance too;
    # EC50_eff = 20 + 0.25*20 = 25, (20/25)^2 = 0.64, ΔMAP = 41*0.64/1.64 = 16 mmHg.
    patient = PkpdPatient(PKPD, 1.0)
    assert patient.max_delta_map_mmhg(30.0) == pytest.approx(16.0, abs=1e-12)
    run(patient, 30.0, 40 * 3600.0, 1.0)  # past the ~3.5 h peripheral creep; no haemorrhage
    assert patient.delta_map_mmhg == pytest.approx(16.0, abs=0.05)
    assert patient.map_mmhg == pytest.approx(71.0, abs=0.05)


def test_pkpd_model_step_follows_the_closed_form_two_compartments_and_effect_site() -> None:
    # Hill 1 and no tolerance: ΔMAP = Emax·Ce/(EC50 + Ce), Ce from the closed form after the delay.
    patient = PkpdPatient(replace(PKPD, hill=1.0, tolerance_gain=0.0), 0.1)
    k10, k12, k21, ke0 = 2.5 / 10.0, 1.0 / 10.0, 1.0 / 150.0, 1.0  # 1/min
    seen = {}
    for k in range(1, 18001):  # 30 min at 0.1 s
        patient.step(30.0)
        seen[k] = patient.delta_map_mmhg
    assert all(seen[k] == 0.0 for k in range(1, 201)) and seen[300] > 0.0  # the 20 s line
    for k in (1200, 6000, 18000):  # 2, 10, 30 min
        _, ce = two_compartment_step((k * 0.1 - 20.0) / 60.0, 50.0, 10.0, k10, k12, k21, ke0)
        # explicit Euler at 0.1 s against time constants of a minute and more: within 0.5 %
        assert seen[k] == pytest.approx(41.0 * ce / (20.0 + ce), rel=5e-3), k
    # the apparent schedule: T = 60·V1/(CL+Q) + lag, τ the line, K the fast rise of one more ml/h
    assert patient.T_s == pytest.approx(600.0 / 3.5 + 60.0)
    assert patient.tau_s == pytest.approx(20.0)
    dc = 100.0 / (60.0 * 3.5)
    assert patient.K == pytest.approx(
        41.0 * (ce + dc) / (20.0 + ce + dc) - 41.0 * ce / (20.0 + ce), rel=1e-2
    )


def test_pkpd_patients_of_a_trial_cohort_are_the_benchmarks_cohort() -> None:
    from pressor.hil_sim.patients.pkpd import draw_patient

    assert PkpdPatient.from_seed(2026 * 1_000_000 + 3, 0.1).p == draw_patient(2026, 3)


# -- phenylephrine-2c -----------------------------------------------------------------------------
LABEL = PhenylephrineParams(
    baseline_mmhg=50.0,
    delay_s=0.0,
    v1_l=20.4,
    k10_per_min=0.124,
    k12_per_min=0.155,
    k21_per_min=0.0314,
    ke0_per_min=0.7,
    emax_mmhg=40.0,
    ec50_ng_ml=40.0,
    counter_gain=0.0,
    counter_tau_s=600.0,
)


def test_phenylephrine_label_kinetics_give_45_and_72_percent_of_steady_plasma_at_10_and_60_min():
    patient = Phenylephrine2C(LABEL, 0.5)
    css = 30.0 * 100.0 / (60.0 * 0.124 * 20.4)  # ng/ml at 30 ml/h of 100 ug/ml
    run(patient, 30.0, 600.0, 0.5)
    assert patient.plasma_ng_ml / css == pytest.approx(0.45, abs=0.005)  # the label-derived 45 %
    run(patient, 30.0, 3000.0, 0.5)
    assert patient.plasma_ng_ml / css == pytest.approx(0.72, abs=0.005)  # and 72 % at 60 min


def test_phenylephrine_step_response_matches_the_closed_form_to_rounding() -> None:
    params = replace(LABEL, delay_s=20.0)  # a whole number of 0.1 s steps: exact
    patient = Phenylephrine2C(params, 0.1)
    seen = {}
    for k in range(1, 36001):  # 60 min
        patient.step(30.0)
        seen[k] = (patient.plasma_ng_ml, patient.delta_map_mmhg)
    assert seen[200] == (0.0, 0.0)
    for k in (300, 1200, 6000, 36000):
        c1, ce = two_compartment_step(
            (k * 0.1 - 20.0) / 60.0, 50.0, 20.4, 0.124, 0.155, 0.0314, 0.7
        )
        assert seen[k][0] == pytest.approx(c1, rel=1e-9)
        assert seen[k][1] == pytest.approx(40.0 * ce / (40.0 + ce), rel=1e-9)
    # apparent schedule: T = 60/(k10 + k12) + 60/ke0, τ the line, K the fast rise of one more ml/h
    assert patient.T_s == pytest.approx(60.0 / 0.279 + 60.0 / 0.7)
    assert patient.tau_s == 20.0
    dc = 100.0 / (60.0 * 20.4 * 0.279)
    assert patient.K == pytest.approx(40.0 * (ce + dc) / (40.0 + ce + dc) - 40.0 * ce / (40.0 + ce))


def test_phenylephrine_counter_regulation_takes_back_its_fraction_at_steady_state() -> None:
    # V1 20 l, k10 0.125/min: CL 2.5 l/min; 30 ml/h -> Css = 3000/(60*2.5) = 20 ng/ml;
    # E = 45*20/(25+20) = 20 mmHg, a quarter taken back: ΔMAP = 15 mmHg.
    params = replace(
        LABEL, v1_l=20.0, k10_per_min=0.125, emax_mmhg=45.0, ec50_ng_ml=25.0, counter_gain=0.25
    )
    patient = Phenylephrine2C(params, 10.0)
    assert patient.max_delta_map_mmhg(30.0) == pytest.approx(15.0, rel=1e-12)
    run(patient, 30.0, 15 * 3600.0, 10.0)  # 17 slow half-lives
    assert patient.delta_map_mmhg == pytest.approx(15.0, abs=1e-3)
    assert patient.counter_mmhg == pytest.approx(5.0, abs=1e-3)


def test_phenylephrine_draws_are_seeded_and_inside_the_documented_ranges() -> None:
    assert draw_params(11) == draw_params(11) != draw_params(12)
    for seed in range(30):
        for name, value in asdict(draw_params(seed)).items():
            lo, hi = RANGES[name]
            assert lo <= value <= hi, (name, value)
    with pytest.raises(ValueError, match="counter_gain=1.5 outside"):
        replace(LABEL, counter_gain=1.5)


# -- registry, plugin, errors ---------------------------------------------------------------------
def test_every_named_model_loads_and_plays_a_world_with_the_same_bytes_per_seed() -> None:
    for name in PATIENT_MODELS:
        model = load_patient_model(name)
        runs = []
        for _ in range(2):
            world = World("paper-tracking", 7, 0.1, patient_model=name)
            assert isinstance(world.patient, model) and isinstance(world.patient, PatientModel)
            for _ in range(900):  # 90 s: past every model's transport delay
                world.apply_command(40.0)
                world.advance()
            runs.append((world.true_map_mmhg(), _obs(world), world.patient.coefficients()))
        assert runs[0] == runs[1], name
        assert runs[0][0] > world.baseline_mmhg, name


def _obs(world: World) -> tuple[float, ...]:
    obs = world.observe()
    return (obs.sim_time_s, obs.map_mmhg, obs.target_mmhg, obs.K, obs.T_s, obs.tau_s)


def _trial(tmp_path: Path, scenario: Path, name: str, *extra: str) -> Path:
    out = tmp_path / name
    argv = ["--controller", "pi", "--patients", "3", "--seed", "4", "--scenario", str(scenario)]
    assert main("trial", [*argv, *extra, "--out", str(out)]) == 0
    return out


def test_a_plugin_model_runs_a_trial_whose_records_and_summary_name_it(
    tmp_path: Path, short_tracking_scenario: Path
) -> None:
    one = _trial(tmp_path, short_tracking_scenario, "one", "--patient-model", PLUGIN)
    two = _trial(tmp_path, short_tracking_scenario, "two", "--patient-model", PLUGIN, "--jobs", "2")
    for f in ("patients.json", "patients.csv", "summary.json"):
        assert (one / f).read_bytes() == (two / f).read_bytes(), f
    summary = json.loads((one / "summary.json").read_text())
    records = json.loads((one / "patients.json").read_text())
    assert summary["patient_model"] == PLUGIN
    assert summary["coefficient_units"] == {
        "K": "mmHg/(ml/h)",
        "T_s": "s",
        "tau_s": "s",
        "baseline_mmhg": "mmHg",
    }
    assert [r["patient_model"] for r in records] == [PLUGIN] * 3
    assert 0.2 <= records[0]["coefficients"]["K"] <= 0.8
    assert (
        (one / "patients.csv")
        .read_text()
        .splitlines()[0]
        .startswith("patient_seed,K (mmHg/(ml/h)),T_s (s),tau_s (s),baseline_mmhg (mmHg)")
    )


@pytest.mark.parametrize(
    ("spec", "needles"),
    [
        ("nope", ["'nope'", "unknown model", "paper, pkpd, phenylephrine-2c"]),
        ("tests.no_such_module:X", ["cannot import module 'tests.no_such_module'"]),
        (
            "tests.support.patient_plugin:Missing",
            ["module 'tests.support.patient_plugin' has no class 'Missing'"],
        ),
        (
            "tests.support.patient_plugin:NoStep",
            ["class 'NoStep'", "'tests.support.patient_plugin'", "step"],
        ),
        ("tests.support.patient_plugin:NoDelay", ["class 'NoDelay'", "no numeric tau_s"]),
    ],
)
def test_a_bad_patient_model_is_one_line_naming_module_class_and_what_is_missing_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], spec: str, needles: list[str]
) -> None:
    argv = ["--patients", "1", "--patient-model", spec, "--out", str(tmp_path / "o")]
    assert main("trial", argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--patient-model" in err[0], err
    for needle in needles:
        assert needle in err[0], (needle, err[0])
    assert not (tmp_path / "o").exists()


def test_a_frozen_scenario_refuses_any_model_but_the_papers(tmp_path, capsys) -> None:
    argv = ["--patients", "1", "--scenario", "nominal-step", "--patient-model", "pkpd"]
    assert main("trial", [*argv, "--out", str(tmp_path / "o")]) == 2
    assert "'nominal-step' fixes a frozen" in capsys.readouterr().err
