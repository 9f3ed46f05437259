"""pressor.hil_sim.native.drug_patient: the compiled pkpd, phenylephrine-2c and norepinephrine patients
are the Python patients, bit for bit, step by step (also inside the responsiveness sweep's wrapper,
at several sensitivity levels), keep their parameters and derived figures, and a trial under the
drug library's dose limits gives the same record with and without every twin."""

from __future__ import annotations

import json
import random

import numpy as np
import pytest

from pressor.hil_sim.native import dose_guard as ndg
from pressor.hil_sim.native import drug_patient as ndp
from pressor.hil_sim.native import patient as npt
from pressor.hil_sim.native.patient import native_patient
from pressor.hil_sim.patients.norepinephrine import Norepinephrine1C
from pressor.hil_sim.patients.patient_model import load_patient_model
from pressor.hil_sim.patients.phenylephrine import Phenylephrine2C
from pressor.hil_sim.patients.pkpd import PkpdPatient
from pressor.hil_sim.scenarios.scenario import load_scenario
from pressor.hil_sim.trials import trial
from pressor.plumbing import native_build as nb
from pressor.runtime.core.dose_guard import DoseLimits

pytestmark = pytest.mark.skipif(nb.compiler() is None, reason="no C compiler")

MODELS = {
    "pkpd": PkpdPatient,
    "phenylephrine-2c": Phenylephrine2C,
    "norepinephrine": Norepinephrine1C,
}
TWINS = {
    PkpdPatient: ndp.NativePkpdPatient,
    Phenylephrine2C: ndp.NativePhenylephrine2C,
    Norepinephrine1C: ndp.NativeNorepinephrine1C,
}


@pytest.fixture(autouse=True)
def native_on(monkeypatch):
    monkeypatch.delenv(nb.NATIVE_ENV, raising=False)


def _read(p) -> tuple[float, ...]:
    """What the world reads every tick, and the ΔMAP the truth records."""
    return (p.map_mmhg, p.delta_map_mmhg, p.K, p.T_s, p.tau_s)


def _infusion(seed: int, n: int) -> list[float]:
    """Holds of 0.5-90 s at 0, a trickle, random rates and the pump's maximum, ramps between."""
    rng = random.Random(seed)
    out: list[float] = []
    while len(out) < n:
        hold = rng.randint(5, 900)
        kind = rng.random()
        if kind < 0.6:
            rate = rng.choice((0.0, 0.3, 120.0, rng.uniform(0.0, 120.0)))
            out += [rate] * hold
        else:  # a ramp, up or down
            a, b = rng.uniform(0.0, 120.0), rng.uniform(0.0, 120.0)
            out += [a + (b - a) * k / hold for k in range(hold)]
    return out[:n]


@pytest.mark.parametrize("model", list(MODELS))
@pytest.mark.parametrize("level", [None, 0.1, 2.0, 10.0])
def test_twin_map_trace_is_the_python_patients_bit_for_bit_at_every_sensitivity(model, level):
    spec = model if level is None else f"{model}@sensitivity={level!r}"
    cls = load_patient_model(spec)
    for seed in (1, 2026000004):
        py, twin = cls.from_seed(seed, 0.1), native_patient(cls.from_seed(seed, 0.1))
        inner = twin if level is None else twin.inner
        assert type(inner) is TWINS[MODELS[model]], npt.last_reason
        assert _read(twin) == _read(py)
        trace_py, trace_twin = [], []
        for rate in _infusion(seed, 36000):  # an hour at 0.1 s
            py.step(rate)
            twin.step(rate)
            trace_py.append(_read(py))
            trace_twin.append(_read(twin))
        assert trace_py == trace_twin
        maps = [r[0] for r in trace_py]
        assert max(maps) - min(maps) > 1.0  # the infusions moved the patient (0.1×: little)


@pytest.mark.parametrize("model", list(MODELS))
def test_twin_keeps_the_patients_parameters_state_and_derived_figures(model):
    py, twin = MODELS[model].from_seed(7, 0.1), native_patient(MODELS[model].from_seed(7, 0.1))
    for p in (py, twin):
        for rate in (40.0,) * 3000 + (0.0,) * 500:
            p.step(rate)
    assert twin.coefficients() == py.coefficients()
    assert twin.baseline_mmhg == py.baseline_mmhg
    assert twin.max_delta_map_mmhg(120.0) == py.max_delta_map_mmhg(120.0)
    states = {
        "pkpd": ("a1_ug", "a2_ug", "ce_ng_ml", "tol_ng_ml", "t_s"),
        "phenylephrine-2c": ("a1_ug", "a2_ug", "ce_ng_ml", "counter_mmhg", "time_s"),
        "norepinephrine": ("plasma_ng_ml", "ce_ng_ml", "counter_mmhg", "time_s"),
    }[model]
    assert [getattr(twin, s) for s in states] == [getattr(py, s) for s in states]


def test_drug_patients_without_a_twin_come_back_unchanged_with_the_reason(monkeypatch):
    for cls in MODELS.values():
        stepped = cls.from_seed(3, 0.1)
        stepped.step(10.0)
        assert native_patient(stepped) is stepped and "already" in npt.last_reason
    long_line = Phenylephrine2C.from_seed(3, 0.001)  # a 10-35 s delay on a 1 ms grid
    assert native_patient(long_line) is long_line and "8192" in npt.last_reason
    monkeypatch.setenv(nb.NATIVE_ENV, "off")
    fresh = Norepinephrine1C.from_seed(3, 0.1)
    assert native_patient(fresh) is fresh and npt.last_reason == "PRESSOR_NATIVE=off"


@pytest.mark.parametrize(
    ("spec", "model"),
    [
        ("lpv:cautious", "pkpd@sensitivity=0.2"),
        # an hour each: the other two models' twins are checked step for step above
        pytest.param("lpv:cautious", "phenylephrine-2c@sensitivity=0.5", marks=pytest.mark.slow),
        pytest.param(
            "lpv:norepinephrine-cautious", "norepinephrine@sensitivity=0.2", marks=pytest.mark.slow
        ),
    ],
)
def test_trial_under_dose_limits_gives_the_same_record_with_and_without_the_twins(
    monkeypatch, spec, model
):
    # 12 ml in any hour: the hourly maximum cuts the command within minutes and its taper walks
    # the leaving segments for the last ten minutes of the hour
    drug_conc = 16.0 if model.startswith("norepinephrine") else 100.0
    limits = DoseLimits(
        hard_max_ml_h=120.0,
        soft_max_ml_h=120.0,
        max_ml_per_hour=12.0,
        concentration_ug_ml=drug_conc,
    )
    sc = load_scenario("paper-disturbance")
    runs = {}
    for mode in ("off", "auto"):
        monkeypatch.setenv(nb.NATIVE_ENV, mode)
        runs[mode] = trial._simulate_patient(sc, spec, 4242, 0.1, "cautious", model, limits)
        assert (npt.last_reason == "") == (mode == "auto"), npt.last_reason
        assert (ndg.last_reason == "") == (mode == "auto"), ndg.last_reason
    (rec_py, traj_py), (rec_c, traj_c) = runs["off"], runs["auto"]
    assert rec_py["dose"]["hour_limited_s"] > 600.0  # the taper had work to do
    assert json.dumps(rec_py) == json.dumps(rec_c)
    for field in ("rate_ml_h", "map_true_mmhg", "command_ml_h", "K", "faults"):
        assert np.array_equal(getattr(traj_py, field), getattr(traj_c, field)), field
