"""pressor.hil_sim.native.patient: the compiled paper patient is the Python patient, bit for bit, step by
step, and keeps its parameters, coefficients and reachability."""

from __future__ import annotations

import math
import random

import pytest

from pressor.hil_sim.native import patient as npt
from pressor.hil_sim.native.patient import NativePatient, native_patient
from pressor.hil_sim.patients.patient import FrozenParams, Patient
from pressor.hil_sim.patients.pkpd import IndependentPatient, draw_patient
from pressor.plumbing import native_build as nb

pytestmark = pytest.mark.skipif(nb.compiler() is None, reason="no C compiler")


@pytest.fixture(autouse=True)
def native_on(monkeypatch):
    monkeypatch.delenv(nb.NATIVE_ENV, raising=False)


def _state(p: Patient) -> tuple[float, ...]:
    return (p.time_s, p.delta_map_mmhg, p.infused_ml_h_s, p.K, p.T_s, p.tau_s, p.map_mmhg)


@pytest.mark.parametrize("seed", [1, 7, 2026])
def test_twin_steps_equal_the_python_patient_through_starts_stops_and_rate_jumps(seed):
    py = Patient.from_seed(seed, 0.1)
    twin = native_patient(Patient.from_seed(seed, 0.1))
    assert isinstance(twin, NativePatient), npt.last_reason
    rng = random.Random(seed)
    rate, tau_max = 0.0, 0.0
    for k in range(30000):
        if k % 600 == 0:  # hold, then jump: 0 (the τ filter's start), up to the pump's limit
            rate = rng.choice((0.0, rng.uniform(0.0, 120.0), 120.0, 3.0))
        py.step(rate)
        twin.step(rate)
        assert _state(py) == _state(twin), k
        tau_max = max(tau_max, py.tau_s)
    assert tau_max > 10.0 and py.K != py.params.k0  # the delay and the gain moved


def test_twin_keeps_the_patients_parameters_and_derived_figures():
    py = Patient.from_seed(3, 0.1)
    twin = native_patient(Patient.from_seed(3, 0.1))
    assert twin.params == py.params and twin.coefficients() == py.coefficients()
    assert twin.baseline_mmhg == py.baseline_mmhg
    assert twin.max_delta_map_mmhg(120.0) == py.max_delta_map_mmhg(120.0)
    assert _state(twin) == _state(py)


def test_patients_without_a_twin_come_back_unchanged_with_the_reason(monkeypatch):
    frozen = Patient(FrozenParams(0.5, 150.0, 40.0, 70.0), 0.1)
    assert native_patient(frozen) is frozen and "nonlinear" in npt.last_reason
    other = IndependentPatient(draw_patient(3, 1), 0.1, 100.0)  # a model no twin mirrors
    assert native_patient(other) is other and "nonlinear" in npt.last_reason
    stepped = Patient.from_seed(3, 0.1)
    stepped.step(10.0)
    assert native_patient(stepped) is stepped and "already" in npt.last_reason
    tiny = Patient.from_seed(3, 0.001)
    assert native_patient(tiny) is tiny and "buffer" in npt.last_reason
    monkeypatch.setenv(nb.NATIVE_ENV, "off")
    fresh = Patient.from_seed(3, 0.1)
    assert native_patient(fresh) is fresh and npt.last_reason == "PRESSOR_NATIVE=off"
    assert math.isfinite(fresh.map_mmhg)
