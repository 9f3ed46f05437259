"""The K-scaled Wirtinger functional: certifies the fast Smith loop the plain one cannot, agrees
with it where K is fixed, and its vertex re-check still rejects an uncertifiable loop."""

from __future__ import annotations

import numpy as np
import pytest

from pressor.synthesis.certificates.interface import AnalysisResult
from pressor.synthesis.certificates.wirtinger.analysis import analyse_wirtinger
from pressor.synthesis.certificates.wirtinger.k_scaling import KScaling, k_scaled_system, k_terms
from pressor.synthesis.families.smith.law import SmithLPV
from pressor.synthesis.problem.closed_loop import DelaySystem, close_loop
from pressor.synthesis.problem.config_toml import parse_config
from pressor.synthesis.problem.model import I_U, plant_at

BOX = np.array([[0.25, 1.0], [100.0, 200.0], [10.0, 45.0]])
HALF = 0.5 * (BOX[:, 1] - BOX[:, 0])
RATES = np.array([2e-4, 0.06, 0.1])  # the shipped rate bounds, K (mmHg/(ml/h))/s, T s/s, tau s/s
SMITH_STATES = (I_U, 3)  # plant infusion u and the controller's model input u-hat (ml/h)


def _smith_corners(loop_gain: float) -> tuple[list[DelaySystem], np.ndarray, np.ndarray]:
    """The Smith loop at the 8 corners of the shipped box; (loops, rho_hat, rho)."""
    model = parse_config({}).model
    rho_hat = np.array([(a, b, c) for a in (-1.0, 1.0) for b in (-1.0, 1.0) for c in (-1.0, 1.0)])
    rhos = 0.5 * (BOX[:, 0] + BOX[:, 1]) + rho_hat * HALF
    loops = [close_loop(plant_at(r, model), SmithLPV(loop_gain).at(r), r[2]) for r in rhos]
    return loops, rho_hat, rhos


def _corners_analysis(loop_gain: float, k_scaled: bool, **kw: object) -> AnalysisResult:
    loops, rho_hat, rhos = _smith_corners(loop_gain)
    ks = KScaling(rhos[:, 0], RATES[0], SMITH_STATES) if k_scaled else None
    return analyse_wirtinger(
        loops,
        rho_hat,
        RATES / HALF,
        np.array([0.0, 0.0, HALF[2]]),
        45.0,
        p_dependence="affine",
        time_scale_s=45.0,
        rate_form="bound",
        k_scaling=ks,
        **kw,
    )


@pytest.mark.slow
def test_k_scaled_functional_certifies_loop_gain_3_that_the_plain_one_cannot() -> None:
    # loop gain 3 (nominal 0 % / 194 s): plain functional infeasible on the corners, all rates on
    plain = _corners_analysis(3.0, k_scaled=False)
    scaled = _corners_analysis(3.0, k_scaled=True)
    assert not plain.certified
    assert scaled.certified and scaled.gamma < 13.49  # below the shipped design's gamma
    assert scaled.n_lmis == 8 * 16  # K, T, tau vertices and the r = K(t)/K(t - tau) vertex


def test_k_scaled_functional_gives_a_lower_gamma_on_a_k_edge() -> None:
    # loop gain 2 on the K edge (T 150 s, tau 27.5 s), only K moving: the Smith gains scale as
    # 1/K, which P affine in K cannot follow in the loop's own coordinates
    model = parse_config({}).model
    ks_ = np.array([0.25, 1.0])
    loops = [
        close_loop(plant_at((k, 150.0, 27.5), model), SmithLPV(2.0).at((k, 150.0, 27.5)), 27.5)
        for k in ks_
    ]
    args = (loops, np.array([[-1.0], [1.0]]), np.array([RATES[0] / HALF[0]]), np.zeros(1), 27.5)
    kw = dict(p_dependence="affine", time_scale_s=45.0, rate_form="bound")
    plain = analyse_wirtinger(*args, **kw)
    scaled = analyse_wirtinger(*args, **kw, k_scaling=KScaling(ks_, RATES[0], SMITH_STATES))
    assert scaled.certified
    assert plain.gamma is None or scaled.gamma < 0.9 * plain.gamma


def test_k_scaled_functional_agrees_with_the_plain_one_where_k_is_fixed() -> None:
    # K_min = K_max = 0.55 (rate 0): x~ = D x with a constant D, a congruence of the same LMI
    model = parse_config({}).model
    rhos = [(0.55, 150.0, tau) for tau in (10.0, 45.0)]
    loops = [close_loop(plant_at(r, model), SmithLPV(2.0).at(r), r[2]) for r in rhos]
    args = (loops, np.array([[-1.0], [1.0]]), np.array([RATES[2] / HALF[2]]))
    args += (np.array([HALF[2]]), 45.0)
    kw = dict(p_dependence="affine", time_scale_s=45.0, rate_form="bound")
    plain = analyse_wirtinger(*args, **kw)
    ks = KScaling(np.array([0.55, 0.55]), 0.0, SMITH_STATES)
    scaled = analyse_wirtinger(*args, **kw, k_scaling=ks)
    assert plain.certified and scaled.certified
    assert scaled.n_lmis == plain.n_lmis == 2 * 2
    assert scaled.gamma == pytest.approx(plain.gamma, rel=2e-3)


def _scalar_grid(k0: float, k1: float) -> tuple[list[DelaySystem], np.ndarray, KScaling]:
    """x' = -0.2 x - k x(t - 1) + w, z = x with x the scaled state, k = k0 + k1 rho: stable at a
    frozen point iff the delayed gain is below the stability limit of the damped loop."""
    rho = np.linspace(-1.0, 1.0, 3)[:, None]
    one = np.ones((1, 1))
    systems = [
        DelaySystem(-0.2 * one, -(k0 + k1 * r) * one, one, one, 0 * one, 0 * one, 1.0)
        for r in rho[:, 0]
    ]
    return systems, rho, KScaling(np.array([0.5, 0.75, 1.0]), 0.01, (0,))


@pytest.mark.parametrize(("k0", "k1", "stable"), [(1.0, 0.2, True), (1.5, 0.6, False)])
def test_vertex_recheck_gives_the_verdict_in_k_scaled_coordinates(
    k0: float, k1: float, stable: bool
) -> None:
    # x' = -0.2 x - 2.1 x(t - 1) is unstable (frequency sweep: a root with Re > 0): the capped
    # feasibility solve returns a point, and the exact re-check of every (K, r) vertex rejects it
    systems, rho, ks = _scalar_grid(k0, k1)
    res = analyse_wirtinger(
        systems,
        rho,
        np.array([0.04]),  # K: 0.01 per s over the half-width 0.25
        np.zeros(1),
        1.0,
        p_dependence="affine",
        rate_form="bound",
        gamma_cap=1e3,
        k_scaling=ks,
    )
    assert res.n_lmis == 3 * 4  # the K vertex (kappa, P rate) times the r vertex
    assert res.certified == stable
    assert (np.min(res.margins) > 0) == stable


def test_k_terms_span_the_r_interval_of_each_point() -> None:
    # Ad at r = K / (K - nu tau_max) and r = K / (K + nu tau_max): the centre +/- the r direction
    loops, _, rhos = _smith_corners(3.0)
    ks = KScaling(rhos[:, 0], RATES[0], SMITH_STATES)
    ad = np.stack(
        [k_scaled_system(q, k, SMITH_STATES).Ad for q, k in zip(loops, rhos[:, 0], strict=True)]
    )
    eye = np.eye(5)
    center, (u_kappa, phi_kappa), (u_r, phi_r), _ = k_terms(ks, ad, eye, eye, 45.0, 45.0, 3)
    d_kappa, d_r = u_kappa @ phi_kappa[:, :5], u_r @ phi_r[:, 5:10]
    pi = np.diag([0.0, 1.0, 0.0, 1.0, 0.0])
    for j, k in enumerate(rhos[:, 0]):
        for r, sign in ((k / (k - RATES[0] * 45.0), 1.0), (k / (k + RATES[0] * 45.0), -1.0)):
            assert np.allclose(center[j] + sign * d_r[j], ad[j] @ (eye + (r - 1.0) * pi))
        assert np.allclose(d_kappa[j], 45.0 * RATES[0] / k * pi)


def test_relative_k_terms_are_the_same_at_every_k() -> None:
    # |d ln K/dt| <= nu: kappa = +/- nu and r in [e^(-nu tau_max), e^(nu tau_max)] at every K
    loops, _, rhos = _smith_corners(3.0)
    nu = 0.01
    ks = KScaling(rhos[:, 0], nu, SMITH_STATES, relative=True)
    ad = np.stack(
        [k_scaled_system(q, k, SMITH_STATES).Ad for q, k in zip(loops, rhos[:, 0], strict=True)]
    )
    eye = np.eye(5)
    center, (u_kappa, phi_kappa), (u_r, phi_r), _ = k_terms(ks, ad, eye, eye, 45.0, 45.0, 3)
    d_kappa, d_r = u_kappa @ phi_kappa[:, :5], u_r @ phi_r[:, 5:10]
    pi = np.diag([0.0, 1.0, 0.0, 1.0, 0.0])
    for j in range(len(rhos)):
        for r, sign in ((np.exp(nu * 45.0), 1.0), (np.exp(-nu * 45.0), -1.0)):
            assert np.allclose(center[j] + sign * d_r[j], ad[j] @ (eye + (r - 1.0) * pi))
        assert np.allclose(d_kappa[j], 45.0 * nu * pi)


def test_kappa_rows_add_their_direction_on_x_x_delayed_and_w() -> None:
    loops, _, rhos = _smith_corners(3.0)
    m = len(rhos)
    rows = np.zeros((m, 5, 13))
    rows[:, 2, 0] = 1.5  # x_e row reads x[0], x_d[4] and w[1]
    rows[:, 2, 5 + 4] = -0.5
    rows[:, 2, 10 + 1] = 2.0
    ks = KScaling(rhos[:, 0], 0.01, SMITH_STATES, relative=True, kappa_rows=rows)
    ad = np.stack(
        [k_scaled_system(q, k, SMITH_STATES).Ad for q, k in zip(loops, rhos[:, 0], strict=True)]
    )
    eye = np.eye(5)
    _, (u_kappa, phi_kappa), _, _ = k_terms(ks, ad, eye, eye, 45.0, 45.0, 3)
    full = np.einsum("mnq,qb->mnb", u_kappa, phi_kappa)  # over [x, x_d, int x, w]
    pi = np.diag([0.0, 1.0, 0.0, 1.0, 0.0])
    want = np.zeros((m, 5, 18))
    want[:, :, :5] = pi
    want[:, 2, 0] += 1.5
    want[:, 2, 9] = -0.5
    want[:, 2, 16] = 2.0
    assert np.allclose(full, 45.0 * 0.01 * want)


def test_k_scaling_rejects_a_delayed_output_on_a_scaled_state_and_k_reaching_zero() -> None:
    one = np.ones((1, 1))
    system = DelaySystem(-one, 0.1 * one, one, one, one, 0 * one, 1.0)
    with pytest.raises(ValueError, match="C_d"):
        k_scaled_system(system, 0.5, (0,))
    with pytest.raises(ValueError, match="reach 0"):
        KScaling(np.array([0.01]), 0.02, (0,)).check(1, 1, 1, 1.0)
