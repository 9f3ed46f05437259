"""The monitor-noise estimate of a window mean (pressor.runtime.estimation.noise)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pressor.runtime.estimation.noise import WindowNoise


@pytest.mark.parametrize("sigma_mmhg", [0.2, 0.7])
def test_white_noise_on_the_window_means_is_read_within_15_percent(sigma_mmhg):
    rng = np.random.default_rng(7)
    noise = WindowNoise(0.05, 2.0)
    for y in 70.0 + sigma_mmhg * rng.standard_normal(2000):
        noise.update(float(y))
    assert math.sqrt(noise.variance) == pytest.approx(sigma_mmhg, rel=0.15)


def test_a_map_moving_along_a_parabola_is_not_read_as_noise():
    noise = WindowNoise(0.05, 2.0)
    for j in range(300):  # a 20 mmHg rise bending over 10 min, no noise
        noise.update(50.0 + 20.0 * (1.0 - (1.0 - j / 300.0) ** 2))
    assert noise.variance == pytest.approx(0.05**2)


def test_one_jump_cannot_inflate_the_estimate():
    noise = WindowNoise(0.05, 2.0)
    for y in [60.0] * 50 + [70.0] * 50:  # a 10 mmHg step between two windows
        noise.update(y)
    assert math.sqrt(noise.variance) < 0.1


def test_missing_windows_are_skipped_and_bad_settings_named():
    noise = WindowNoise(0.05, 2.0)
    for y in (60.0, math.nan, 61.0, 60.0):
        assert noise.update(y) == pytest.approx(0.05**2)
    with pytest.raises(ValueError, match="floor_mmhg"):
        WindowNoise(0.0, 2.0)
    with pytest.raises(ValueError, match="memory_s"):
        WindowNoise(0.05, 2.0, memory_s=1.0)
