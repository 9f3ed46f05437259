"""MAP monitor: sampling, quantisation, seeded noise, artifacts; disturbances."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pressor.hil_sim.devices.sensor import (
    QUALITY_HELD,
    QUALITY_INVALID,
    Artifact,
    Sensor,
    SensorConfig,
)
from pressor.hil_sim.patients.cohort import patient_rng
from pressor.hil_sim.scenarios.disturbance import Bolus, DisturbanceSum, Hemorrhage, Sinusoid


def _read(sensor: Sensor, truth, n: int, ts: float = 0.1) -> list[tuple[float, int]]:
    return [sensor.read(k * ts, truth(k * ts)) for k in range(n)]


def test_sample_and_hold_at_monitor_period_and_quantisation():
    s = Sensor(SensorConfig(period_s=1.0, quantum_mmhg=1.0))
    out = _read(s, lambda t: 60.0 + t, 25)
    values = [v for v, _ in out]
    assert values[:10] == [60.0] * 10 and values[10] == 61.0 and values[24] == 62.0
    # a repeat between two monitor updates carries QUALITY_HELD; an update does not
    assert [q for _, q in out] == [0 if k % 10 == 0 else QUALITY_HELD for k in range(25)]


def test_a_monitor_as_fast_as_the_loop_never_holds():
    out = _read(Sensor(SensorConfig(period_s=0.1)), lambda t: 60.0 + t, 50)
    assert all(q == 0 for _, q in out)


def test_noise_is_seeded_and_has_configured_std():
    cfg = SensorConfig(noise_std_mmhg=2.0)
    a = [v for v, _ in _read(Sensor(cfg, patient_rng(4, 1)), lambda t: 70.0, 5000)]
    b = [v for v, _ in _read(Sensor(cfg, patient_rng(4, 1)), lambda t: 70.0, 5000)]
    c = [v for v, _ in _read(Sensor(cfg, patient_rng(5, 1)), lambda t: 70.0, 5000)]
    assert a == b and a != c
    assert np.std(a) == pytest.approx(2.0, rel=0.05) and np.mean(a) == pytest.approx(70.0, abs=0.1)


def test_flush_reads_flush_pressure_and_disconnect_reads_zero_unflagged():
    cfg = SensorConfig(artifacts=(Artifact("flush", 1.0, 0.5), Artifact("disconnect", 2.0, 0.5)))
    out = _read(Sensor(cfg), lambda t: 70.0, 30)
    assert out[5] == (70.0, 0)
    assert out[12] == (300.0, 0)
    assert out[22] == (0.0, 0)
    assert out[27] == (70.0, 0)


def test_monitor_fault_reports_nan_flagged_invalid():
    cfg = SensorConfig(artifacts=(Artifact("monitor_fault", 1.0, 1.0),))
    out = _read(Sensor(cfg), lambda t: 70.0, 30)
    assert math.isnan(out[15][0]) and out[15][1] == QUALITY_INVALID
    assert out[25] == (70.0, 0)


def test_damping_lags_a_step_with_its_time_constant():
    cfg = SensorConfig(artifacts=(Artifact("damping", 0.0, 100.0, time_const_s=10.0),))
    out = _read(Sensor(cfg), lambda t: 60.0 if t < 1.0 else 80.0, 120)
    # The lag sees the truth at each tick (held over the tick before it): at tick 110 it has
    # filtered 101 ticks of the new level, 1 - e^(-10.1/10) of the step.
    assert out[110][0] == pytest.approx(60.0 + 20.0 * (1 - math.exp(-1.01)), abs=1e-9)
    assert out[5][0] == 60.0


def test_hemorrhage_ramps_down_and_stays():
    h = Hemorrhage(start_s=100.0, ramp_s=50.0, depth_mmhg=10.0)
    assert h(100.0) == 0.0 and h(125.0) == pytest.approx(-5.0) and h(1000.0) == -10.0


def test_bolus_rises_then_decays_and_sum_combines():
    b = Bolus(start_s=0.0, rise_s=60.0, amplitude_mmhg=8.0, decay_s=600.0)
    assert b(30.0) == pytest.approx(4.0) and b(60.0) == pytest.approx(8.0)
    assert b(660.0) == pytest.approx(8.0 * math.exp(-1.0))
    s = Sinusoid(start_s=0.0, amplitude_mmhg=3.0, period_s=400.0)
    assert s(100.0) == pytest.approx(3.0)
    total = DisturbanceSum([b, s, Hemorrhage(0.0, 0.0, 2.0)])
    assert total(100.0) == pytest.approx(b(100.0) + 3.0 - 2.0)
    assert DisturbanceSum()(5.0) == 0.0
