"""Rightmost characteristic roots of frozen delay systems against analytically known cases."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import lambertw

from pressor.synthesis.verification.delay_stability import (
    chebyshev_differentiation,
    rightmost_roots,
    spectral_abscissa,
)
from pressor.synthesis.verification.pi_baseline import PIBaseline


@pytest.mark.parametrize("a_tau", [0.5, 1.2, 1.50, 1.55])
def test_pure_delayed_feedback_below_pi_over_2_is_stable(a_tau: float) -> None:
    # x' = -a x(t - tau) is stable iff a tau < pi/2 (Hayes 1950)
    tau = 2.0
    assert spectral_abscissa(np.zeros((1, 1)), np.array([[-a_tau / tau]]), tau) < 0.0


@pytest.mark.parametrize("a_tau", [1.59, 1.7, 3.0])
def test_pure_delayed_feedback_above_pi_over_2_is_unstable(a_tau: float) -> None:
    tau = 2.0
    assert spectral_abscissa(np.zeros((1, 1)), np.array([[-a_tau / tau]]), tau) > 0.0


def test_pure_delayed_feedback_at_pi_over_2_has_roots_on_the_imaginary_axis() -> None:
    # at a tau = pi/2 the rightmost pair is exactly s = +- i a
    tau, a = 3.0, np.pi / 6.0
    roots = rightmost_roots(np.zeros((1, 1)), np.array([[-a]]), tau, count=2).roots
    assert np.allclose(sorted(roots.imag), [-a, a], atol=1e-10)
    assert np.allclose(roots.real, 0.0, atol=1e-10)


@pytest.mark.parametrize(("a", "b", "tau"), [(-1.0, -2.0, 1.3), (0.5, -1.0, 0.4), (-0.2, 0.1, 5.0)])
def test_scalar_roots_match_lambert_w_branches(a: float, b: float, tau: float) -> None:
    # s = a + W_k(b tau e^{-a tau}) / tau; for scalar real systems k = 0 gives the rightmost root
    exact = np.array([a + lambertw(b * tau * np.exp(-a * tau), k) / tau for k in (0, -1, 1, -2, 2)])
    got = rightmost_roots(np.array([[a]]), np.array([[b]]), tau, count=5).roots
    exact = exact[np.argsort(-exact.real, kind="stable")]
    assert abs(got[0].real - exact[0].real) < 1e-10
    for s in exact:
        assert np.min(np.abs(got - s)) < 1e-9


def test_zero_delay_gives_eigenvalues_of_a_plus_ad() -> None:
    a = np.array([[0.0, 1.0], [-2.0, -3.0]])
    ad = np.array([[0.0, 0.0], [0.5, 0.0]])
    roots = rightmost_roots(a, ad, 0.0, count=2).roots
    assert np.allclose(sorted(roots.real), sorted(np.linalg.eigvals(a + ad).real))


def test_refined_roots_make_the_characteristic_matrix_singular() -> None:
    rng = np.random.default_rng(7)
    a = rng.normal(size=(5, 5)) - 2.0 * np.eye(5)
    ad = rng.normal(size=(5, 5))
    res = rightmost_roots(a, ad, 0.8, count=4)
    assert res.refined.all()
    assert np.max(res.residuals) < 1e-10


def test_chebyshev_matrix_differentiates_cubics_exactly() -> None:
    x, d = chebyshev_differentiation(6)
    assert np.allclose(d @ (x**3 - 2 * x), 3 * x**2 - 2, atol=1e-12)


def test_pi_loop_on_nominal_plant_is_stable_and_five_fold_gain_is_not() -> None:
    nominal = PIBaseline().closed_loop(0.55, 150.0, 40.0)
    assert spectral_abscissa(nominal.A, nominal.Ad, nominal.tau) < 0.0
    # kp = 15 (ml/h)/mmHg pushes the loop gain past the delay margin
    hot = PIBaseline(kp=15.0).closed_loop(0.55, 150.0, 40.0)
    assert spectral_abscissa(hot.A, hot.Ad, hot.tau) > 0.0


def test_invalid_inputs_are_rejected_with_a_clear_message() -> None:
    with pytest.raises(ValueError, match="tau"):
        rightmost_roots(np.eye(2), np.eye(2), -1.0)
    with pytest.raises(ValueError, match="square"):
        rightmost_roots(np.eye(2), np.eye(3), 1.0)
    with pytest.raises(ValueError, match="finite"):
        rightmost_roots(np.array([[np.nan]]), np.eye(1), 1.0)
