"""Infusion pump: clamping, resolution, latency, volume, alarms, watchdog."""

from __future__ import annotations

import math

import pytest

from pressor.hil_sim.devices.pump import (
    ALARM_INVALID_COMMAND,
    ALARM_OCCLUSION,
    ALARM_OUT_OF_RANGE,
    ALARM_RESERVOIR_EMPTY,
    ALARM_WATCHDOG,
    Pump,
    PumpConfig,
)


def test_commands_are_clamped_to_zero_and_max_and_counted():
    pump = Pump(PumpConfig(max_rate_ml_h=120.0))
    assert pump.command(500.0) == 120.0
    assert pump.alarms & ALARM_OUT_OF_RANGE
    assert pump.command(-3.0) == 0.0
    assert pump.command(50.0) == 50.0
    assert not pump.alarms & ALARM_OUT_OF_RANGE
    assert pump.commands_out_of_range == 2


def test_rate_is_rounded_to_resolution():
    pump = Pump(PumpConfig(resolution_ml_h=0.5))
    assert pump.command(10.26) == 10.5
    assert pump.command(10.24) == 10.0


def test_latency_delays_the_rate_change_inside_a_step():
    pump = Pump(PumpConfig(latency_s=0.25, watchdog_s=100.0))
    pump.command(100.0)
    means = [pump.advance(0.1) for _ in range(4)]
    assert means[:2] == [0.0, 0.0]
    assert means[2] == pytest.approx(50.0)  # takes effect half-way through [0.2, 0.3]
    assert means[3] == pytest.approx(100.0)


def test_volume_integrates_delivered_rate():
    pump = Pump(PumpConfig(watchdog_s=1e6))
    pump.command(36.0)  # 36 ml/h = 0.01 ml/s
    for _ in range(1000):
        pump.advance(0.1)
    assert pump.volume_ml == pytest.approx(1.0)


def test_watchdog_goes_to_safe_rate_with_alarm_and_a_valid_command_resumes():
    pump = Pump(PumpConfig(watchdog_s=2.0, safe_rate_ml_h=5.0))
    pump.command(80.0)
    rates = []
    for _ in range(30):
        pump.command(math.nan)  # invalid commands do not feed the watchdog
        assert pump.alarms & ALARM_INVALID_COMMAND
        rates.append(pump.advance(0.1))
    assert rates[18] == 80.0 and rates[19] == 5.0  # 2.0 s without a valid command
    assert pump.alarms & ALARM_WATCHDOG and pump.delivered_ml_h == 5.0
    pump.command(40.0)
    assert pump.advance(0.1) == 40.0 and not pump.alarms & ALARM_WATCHDOG


def test_occlusion_stops_delivery_and_raises_alarm_for_its_window():
    pump = Pump(PumpConfig(occlusion_start_s=1.0, occlusion_duration_s=1.0, watchdog_s=1e6))
    pump.command(60.0)
    means = [pump.advance(0.5) for _ in range(6)]
    assert means == [60.0, 60.0, 0.0, 0.0, 60.0, 60.0]
    pump2 = Pump(PumpConfig(occlusion_start_s=0.0, watchdog_s=1e6))
    pump2.command(60.0)
    pump2.advance(0.1)
    assert pump2.alarms & ALARM_OCCLUSION and pump2.volume_ml == 0.0


def test_empty_reservoir_stops_exactly_at_its_volume():
    pump = Pump(PumpConfig(reservoir_ml=0.01, watchdog_s=1e6))
    pump.command(36.0)  # 0.01 ml/s: empty after exactly 1 s
    means = [pump.advance(0.3) for _ in range(5)]
    assert means[3] == pytest.approx(36.0 / 3.0)  # 0.1 of the 0.3 s step
    assert means[4] == 0.0 and pump.volume_ml == pytest.approx(0.01)
    assert pump.alarms & ALARM_RESERVOIR_EMPTY and pump.delivered_ml_h == 0.0


def test_bad_config_is_rejected():
    with pytest.raises(ValueError, match="safe_rate"):
        PumpConfig(max_rate_ml_h=100.0, safe_rate_ml_h=200.0)
