"""The frontier harness's truth source and its not-shipped designs (research/schedule_sources.py,
research/designs/)."""

from __future__ import annotations

from pathlib import Path

import pytest

from pressor.hil_sim.patients.pkpd import PatientParams
from pressor.runtime.core.scheduling import ScheduleInput
from pressor.runtime.inputs.controller_loader import load_controller
from pressor.synthesis.problem.config_toml import load_config
from research.schedule_labels import make_source
from research.step_fit import apparent_fopdt

DESIGNS = Path(__file__).parents[2] / "research" / "designs"


def _patient(q_l_min: float) -> PatientParams:
    # hand-checkable: Hill 1, no tolerance; the disturbance fields do not enter the steady state
    return PatientParams(
        baseline_mmhg=50.0, delay_s=20.0, cl_l_min=2.0, v1_l=10.0, q_l_min=q_l_min, v2_l=200.0,
        effect_lag_s=60.0, emax_mmhg=60.0, ec50_ng_ml=30.0, hill=1.0, tolerance_tau_s=1800.0,
        tolerance_gain=0.0, hemorrhage_mmhg=10.0, hemorrhage_ramp_s=60.0, bolus_mmhg=8.0,
        bolus_rise_s=90.0, bolus_decay_s=600.0,
    )  # fmt: skip


@pytest.mark.parametrize(("q_l_min", "T_s"), [(0.0, 360.0), (1.0, 260.0)])
def test_apparent_fopdt_is_the_secant_gain_to_the_target_and_the_two_fast_lags(q_l_min, T_s):
    # +20 mmHg = 60 C / (30 + C) at C = 15 ng/ml; C = R * 100 / (60 * 2) gives R = 18 ml/h, so
    # K = 20 / 18; T = 60 V1 / (CL + Q) + the effect lag; tau the delay
    K, T, tau = apparent_fopdt(_patient(q_l_min), 70.0)
    assert K == pytest.approx(20.0 / 18.0, rel=1e-6)
    assert T == pytest.approx(T_s)
    assert tau == 20.0


def test_truth_source_holds_the_patients_values_clamped_to_the_controllers_box():
    source = make_source("truth", load_controller("lpv"), (3.5, 450.0, 20.0))
    s = source.update(ScheduleInput(60.0, 0, 0.0, 0.5, 120.0, 30.0, True))
    assert (s.K, s.T_s, s.tau_s) == (3.0, 400.0, 20.0)  # the shipped box: K <= 3, T <= 400 s


def test_not_shipped_designs_widen_the_box_and_keep_the_shipped_law():
    shipped = load_config(None)
    lambdas = {"wide_box.toml": shipped.reference.lambda_s, "wide_box_slow_prefilter.toml": 150.0}
    for name, lam in lambdas.items():
        cfg = load_config(DESIGNS / name)
        assert cfg.model.box.tolist() == [
            [0.05, 5.0],
            [100.0, 400.0],
            shipped.model.box[2].tolist(),
        ]
        # the K rate of the box they were measured with, the other rates the shipped ones
        assert cfg.model.rate_bounds.tolist() == [2e-4, *shipped.model.rate_bounds.tolist()[1:]]
        assert cfg.controller == shipped.controller
        assert cfg.reference.lambda_s == lam
