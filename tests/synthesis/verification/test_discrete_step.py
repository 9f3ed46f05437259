"""The sampled first-order-plus-delay patient every discrete step and frozen-loop check uses."""

from __future__ import annotations

import math

import pytest

from pressor.synthesis.verification.discrete_step import sampled_fopdt


@pytest.mark.parametrize(("k", "t_s", "tau_s"), [(0.55, 150.0, 40.05), (0.1, 40.0, 12.37)])
def test_the_coefficients_are_the_zero_order_hold_closed_form(k, t_s, tau_s):
    ts = 0.1
    p = sampled_fopdt(k, t_s, tau_s, ts)
    assert p.whole == math.floor(tau_s / ts) and p.frac == pytest.approx(tau_s / ts - p.whole)
    late = math.exp(-(1.0 - p.frac) * ts / t_s)
    assert p.a == math.exp(-ts / t_s)
    assert p.b_new == pytest.approx(k * (1.0 - late), rel=1e-12)
    assert p.b_old == pytest.approx(k * late * (1.0 - math.exp(-p.frac * ts / t_s)), rel=1e-9)
    assert p.b_new + p.b_old == pytest.approx(k * (1.0 - p.a), rel=1e-12)  # the DC gain K


def test_a_whole_number_of_samples_keeps_its_tick():
    p = sampled_fopdt(0.55, 150.0, 0.3, 0.1)  # 0.3 / 0.1 = 2.9999999999999996
    assert (p.whole, p.frac, p.b_old) == (3, 0.0, 0.0)
