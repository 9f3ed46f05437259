"""pressor.hil_sim.native.controller: the shipped LPV module's compiled C twin is the Python float step, bit for
bit; and a trial gives the same record and trajectory with all the twins (controller, estimator,
patient, also inside the responsiveness sweep's wrapper) as without them."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from pressor.contracts.drug import binding_of
from pressor.hil_sim.native import controller as nc
from pressor.hil_sim.native import estimator as ne
from pressor.hil_sim.native import patient as npt
from pressor.hil_sim.native.controller import native_twin
from pressor.hil_sim.scenarios.scenario import load_scenario
from pressor.hil_sim.trials import trial
from pressor.plumbing import native_build as nb
from pressor.runtime.core.supervisor_config import sched_limits_of
from pressor.runtime.inputs.controller_loader import (
    GENERATED_DIR,
    load_controller,
    load_generated_module,
)
from tests.support.codegen_helpers import random_inputs

pytestmark = pytest.mark.skipif(nb.compiler() is None, reason="no C compiler")


@pytest.fixture(autouse=True)
def native_on(monkeypatch):
    monkeypatch.delenv(nb.NATIVE_ENV, raising=False)


#: every shipped module with a C twin beside it
TWINNED = ("lpv", "lpv:cautious", "lpv:norepinephrine-cautious")


def _twin(spec: str = "lpv"):
    twin = native_twin(load_controller(spec))
    assert nc.last_reason == "", nc.last_reason
    return twin


def _log_k_inputs(seed: int, n: int):
    """random_inputs with K swept over four decades (0.003-30 mmHg/(ml/h)): a log-K box's range."""
    return [
        (mp, target, 10.0 ** (-2.5 + 4.0 * (0.5 + 0.5 * np.sin(k / 1500.0))), T, tau)
        for k, (mp, target, _, T, tau) in enumerate(random_inputs(seed, n))
    ]


@pytest.mark.parametrize("spec", TWINNED)
def test_twin_steps_flags_state_and_reference_equal_the_python_float_module(spec):
    py, twin = load_controller(spec), _twin(spec)
    assert type(twin) is not type(py)
    inputs = random_inputs(7, 8000) + (_log_k_inputs(8, 8000) if spec != "lpv" else [])
    for k, args in enumerate(inputs):
        assert twin.step(*args) == py.step(*args), (k, args)
        a, b = py.status, twin.status
        assert (a.saturated, a.rho_clamped, a.rho_rate_limited, a.input_invalid) == (
            b.saturated, b.rho_clamped, b.rho_rate_limited, b.input_invalid
        ), k  # fmt: skip
        assert twin.state() == py.state() and twin.reference() == py.reference(), k
    assert isinstance(twin.status.saturated, bool)


def test_reset_twin_continues_like_a_fresh_python_controller():
    twin = _twin()
    for args in random_inputs(3, 500):
        twin.step(*args)
    twin.reset()
    assert twin.state() == (0.0,) * 7
    fresh = load_controller("lpv")
    for args in random_inputs(4, 2000):
        assert twin.step(*args) == fresh.step(*args)


def test_twin_declares_the_modules_box_rates_drug_and_period():
    py, twin = load_controller("lpv"), _twin()
    assert sched_limits_of(twin) == sched_limits_of(py) != (None, None)
    assert binding_of(twin) == binding_of(py)
    assert (twin.sample_period_s, twin.max_rate_ml_h) == (py.sample_period_s, py.max_rate_ml_h)


@pytest.mark.parametrize(
    ("spec", "schedule", "model"),
    [
        ("lpv", "estimated", "paper"),
        ("lpv", "oracle", "paper"),
        ("lpv", "estimated", "paper@sensitivity=5"),
        ("lpv:cautious", "cautious", "paper@sensitivity=10"),
        ("lpv:norepinephrine-cautious", "cautious", "norepinephrine@sensitivity=0.2"),
    ],
)
def test_trial_record_and_trajectory_are_the_same_bytes_with_and_without_the_twins(
    monkeypatch, spec, schedule, model
):
    sc = load_scenario("paper-disturbance")
    runs = {}
    for mode in ("off", "auto"):
        monkeypatch.setenv(nb.NATIVE_ENV, mode)
        runs[mode] = trial._simulate_patient(sc, spec, 4242, 0.1, schedule, model)
    assert nc.last_reason == ""
    assert npt.last_reason == "" or not model.startswith("paper")  # the paper's has a twin
    assert ne.last_reason == "" or schedule != "estimated"
    (rec_py, traj_py), (rec_c, traj_c) = runs["off"], runs["auto"]
    assert json.dumps(rec_py) == json.dumps(rec_c)
    for field in ("rate_ml_h", "map_true_mmhg", "sched_K", "sched_T_s", "sched_tau_s"):
        assert np.array_equal(getattr(traj_py, field), getattr(traj_c, field)), field


def test_controllers_without_a_twin_come_back_unchanged_with_the_reason(monkeypatch):
    for spec in ("pi", "smith"):
        c = load_controller(spec)
        assert native_twin(c) is c and "no compiled twin" in nc.last_reason
    fixed = load_controller("lpv")
    fixed.fixed_point = True
    assert native_twin(fixed) is fixed
    nore = load_controller("lpv:norepinephrine")
    assert native_twin(nore) is nore and "no C twin beside" in nc.last_reason
    monkeypatch.setenv(nb.NATIVE_ENV, "off")
    lpv = load_controller("lpv")
    assert native_twin(lpv) is lpv and nc.last_reason == "PRESSOR_NATIVE=off"


def test_c_twin_of_another_artifact_is_not_used(tmp_path):
    for name in ("lpv_map_controller.py", "lpv_map_controller.c", "lpv_map_controller.h"):
        shutil.copy(GENERATED_DIR / name, tmp_path / name)
    header = tmp_path / "lpv_map_controller.h"
    text = header.read_text()
    sha = text.split('LPVMAP_ARTIFACT_SHA256 "')[1][:64]
    header.write_text(text.replace(sha, "0" * 64))
    mod = load_generated_module(tmp_path / "lpv_map_controller.py")
    c = mod.Controller()
    assert native_twin(c) is c and "another artifact" in nc.last_reason
