"""The committed generated LPV module, closed around the simulated patient, does what synthesis verified.

These tie the whole chain together: synthesis's continuous-time nominal step (embedded in the shipped
artifact by ``pressor verify``) against the generated, sampled, clamped and anti-windup-protected
module that the runtime actually loads, on the frozen nominal plant of the ``nominal-step`` scenario.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pressor.contracts.metrics import step_metrics
from pressor.hil_sim.episode import simulate
from pressor.hil_sim.world import World
from pressor.runtime.inputs.controller_loader import load_controller

ROOT = Path(__file__).resolve().parents[2]
HORIZON_S = 1500.0


@pytest.fixture(scope="module")
def verified_step() -> dict:
    from pressor.synthesis.artifact import load_artifact

    artifact = load_artifact(ROOT / "synthesis" / "data" / "default_design.npz")
    return artifact.metadata["verification"]["nominal_step"]["lpv"]


@pytest.fixture(scope="module")
def lpv_step():
    trajectory = simulate(World("nominal-step", 0, 0.1), load_controller("lpv"), HORIZON_S)
    metrics = step_metrics(
        trajectory.t_s, trajectory.map_true_mmhg, trajectory.target_mmhg, 0.0, 20.0
    )
    return trajectory, metrics


def test_lpv_starts_infusing_within_a_minute_of_a_target_step(lpv_step):
    trajectory, _ = lpv_step
    first_minute = trajectory.command_ml_h[trajectory.t_s <= 60.0]
    assert first_minute.max() > 1.0  # a controller latched at 0 ml/h by its anti-windup fails here


def test_generated_lpv_reproduces_the_verified_continuous_nominal_step(lpv_step, verified_step):
    _, metrics = lpv_step
    # Sampling at 0.1 s, the zero-order hold and clamping u at 0 ml/h (the continuous design dips
    # to -0.01 ml/h) move the response by a few seconds at most.
    assert metrics["rise_time_s"] == pytest.approx(verified_step["rise_time_s"], abs=5.0)
    assert metrics["settling_time_s"] == pytest.approx(verified_step["settling_time_s"], abs=10.0)
    assert metrics["overshoot_pct"] == pytest.approx(verified_step["overshoot_pct"], abs=0.5)


def test_lpv_commands_stay_within_pump_limits_and_reach_the_target(lpv_step):
    trajectory, metrics = lpv_step
    assert np.all((trajectory.command_ml_h >= 0.0) & (trajectory.command_ml_h <= 120.0))
    assert abs(metrics["steady_state_dev_mmhg"]) < 0.1
