"""The delay-dependent analysis LMI certifies stable delay loops and refuses unstable ones."""

from __future__ import annotations

import numpy as np
import pytest

from synthesis.analysis_lmi import analyse, conditioning_transform, whitening_transform
from synthesis.closed_loop import DelaySystem
from synthesis.pi_baseline import PIBaseline


def _scalar(a: float, ad: float, tau: float) -> DelaySystem:
    one = np.ones((1, 1))
    return DelaySystem(a * one, ad * one, one, one, 0 * one, 0 * one, tau)


def _single(system: DelaySystem, **kw) -> object:
    return analyse([system], np.zeros((1, 1)), np.zeros(1), np.zeros(1), system.tau, **kw)


def test_pi_loop_on_nominal_plant_is_certified() -> None:
    res = _single(PIBaseline().closed_loop(0.55, 150.0, 40.0), p_dependence="constant")
    assert res.certified
    assert np.all(res.margins > 0) and np.all(res.p_min_eig > 0)
    assert 0.0 < res.gamma < 10.0


def test_pi_loop_past_its_delay_margin_is_not_certified() -> None:
    # kp = 15 (ml/h)/mmHg: the rightmost roots are in the right half-plane (delay-stability test)
    res = _single(PIBaseline(kp=15.0).closed_loop(0.55, 150.0, 40.0), p_dependence="constant")
    assert not res.certified


def test_gamma_is_a_valid_upper_bound_on_the_exact_l2_gain() -> None:
    # x' = -x + 0.1 x(t - 1) + w, z = x: H-infinity norm is the DC gain 1 / (1 - 0.1)
    res = _single(_scalar(-1.0, 0.1, 1.0), backoff=0.0)
    assert res.certified
    assert 1.0 / 0.9 - 1e-6 <= res.gamma <= 1.0 / 0.9 * 1.01


def test_pure_delayed_feedback_certified_well_inside_the_pi_over_2_bound_only() -> None:
    # x' = -x(t - tau) is stable iff tau < pi/2; a sufficient LMI may certify less, never more
    assert _single(_scalar(0.0, -1.0, 1.0)).certified
    assert not _single(_scalar(0.0, -1.0, 1.7)).certified


def test_parameter_dependent_p_with_rate_vertices_on_a_small_grid() -> None:
    # x' = -(1 + 0.5 rho) x + 0.2 x(t - tau(rho)), tau = 0.5 + 0.25 rho, rho in [-1, 1]
    rho = np.linspace(-1.0, 1.0, 5)[:, None]
    systems = [_scalar(-(1.0 + 0.5 * r), 0.2, 0.5 + 0.25 * r) for r in rho[:, 0]]
    res = analyse(systems, rho, np.array([0.1]), np.array([0.25]), 0.75, p_dependence="affine")
    assert res.certified
    assert res.n_lmis == 5 * 2  # two rate vertices per point
    assert res.margins.shape == (5,)


def test_delay_rate_of_one_or_more_is_rejected() -> None:
    with pytest.raises(ValueError, match="1 s/s"):
        analyse([_scalar(-1.0, 0.1, 1.0)], np.zeros((1, 1)), np.array([4.0]), np.array([0.5]), 1.0)


def test_delay_above_tau_max_is_rejected() -> None:
    with pytest.raises(ValueError, match="tau_max_s"):
        analyse([_scalar(-1.0, 0.1, 2.0)], np.zeros((1, 1)), np.zeros(1), np.zeros(1), 1.0)


def test_quadratic_p_certifies_what_affine_does_with_no_larger_gamma() -> None:
    # P quadratic in rho contains the affine family, so its optimal gamma cannot be larger
    rho = np.linspace(-1.0, 1.0, 5)[:, None]
    systems = [_scalar(-(1.0 + 0.5 * r * r), 0.2, 0.5 + 0.25 * r) for r in rho[:, 0]]
    args = (systems, rho, np.array([0.1]), np.array([0.25]), 0.75)
    aff = analyse(*args, p_dependence="affine", backoff=0.0)
    quad = analyse(*args, p_dependence="quadratic", backoff=0.0)
    assert aff.certified and quad.certified
    assert quad.gamma <= aff.gamma * (1 + 1e-4)


def test_whitening_maps_the_lyapunov_matrix_to_identity() -> None:
    p = np.array([[4.0, 1.0], [1.0, 1e-3 + 0.25]])
    t = whitening_transform(p)
    assert np.allclose(t.T @ p @ t, np.eye(2), atol=1e-9)
    with pytest.raises(ValueError, match="positive definite"):
        whitening_transform(-p)


def test_conditioning_transform_keeps_the_certificate_of_the_pi_loop() -> None:
    # a constant congruence changes conditioning, not feasibility
    cl = PIBaseline().closed_loop(0.55, 150.0, 40.0)
    first = _single(cl, p_dependence="constant")
    t = conditioning_transform(first.p0_phys, cl, 40.0)
    again = _single(cl, p_dependence="constant", state_transform=t)
    assert again.certified
    assert again.gamma == pytest.approx(first.gamma, rel=2e-2)


def test_feasibility_form_with_gamma_cap_below_the_true_gain_is_not_certified() -> None:
    # exact L2 gain 1/0.9 = 1.11: a cap of 1.0 cannot be met, a cap of 2.0 can
    assert not _single(_scalar(-1.0, 0.1, 1.0), gamma_cap=1.0).certified
    ok = _single(_scalar(-1.0, 0.1, 1.0), gamma_cap=2.0)
    assert ok.certified and ok.gamma <= 2.0 + 1e-6


def _theorem1_unrescaled(
    cert: dict,
    system: DelaySystem,
    rho: float,
    sigma: float,
    gamma: float,
    rate: float,
    dtau_drho: float,
    tau_max: float,
) -> np.ndarray:
    """The printed 5-block Theorem-1 LMI (with the -R and -gamma I blocks) at one point/vertex."""
    tx, ts = cert["transform"], cert["time_scale_s"]
    txi = np.linalg.inv(tx)
    a, ad = ts * txi @ system.A @ tx, ts * txi @ system.Ad @ tx
    b, c, cd, d = ts * txi @ system.B, system.C @ tx, system.Cd @ tx, system.D
    p = cert["P"][0] + rho * cert["P"][1]  # affine P
    dp = sigma * rate * ts * cert["P"][1]
    q, r, tb = cert["Q"], cert["R"], tau_max / ts
    dtau = sigma * rate * dtau_drho
    n, nw, nz = a.shape[0], b.shape[1], c.shape[0]
    z = np.zeros
    m = np.block(
        [
            [p @ a + a.T @ p + dp + q - r, p @ ad + r, p @ b, c.T, tb * a.T @ r],
            [(p @ ad + r).T, -(1 - dtau) * q - r, z((n, nw)), cd.T, tb * ad.T @ r],
            [(p @ b).T, z((nw, n)), -gamma * np.eye(nw), d.T, tb * b.T @ r],
            [c, cd, d, -gamma * np.eye(nz), z((nz, n))],
            [tb * r @ a, tb * r @ ad, tb * r @ b, z((n, nz)), -r],
        ]
    )
    return 0.5 * (m + m.T)


def test_returned_certificate_satisfies_the_printed_unrescaled_lmi_at_the_reported_gain() -> None:
    # the certificate is what a controller step holds fixed: it must satisfy the 5-block LMI of
    # the module docstring (not the solved, rescaled form) at every point and rate vertex
    rho = np.linspace(-1.0, 1.0, 3)[:, None]
    systems = [_scalar(-(1.0 + 0.5 * r), 0.2, 0.5 + 0.25 * r) for r in rho[:, 0]]
    res = analyse(systems, rho, np.array([0.1]), np.array([0.25]), 0.75, p_dependence="affine")
    assert res.certified and res.certificate is not None
    cert = res.certificate
    assert cert["P"].shape == (2, 1, 1) and cert["Q"].shape == (1, 1)
    worst = max(
        np.linalg.eigvalsh(
            _theorem1_unrescaled(cert, s, float(r[0]), sg, res.gamma, 0.1, 0.25, 0.75)
        )[-1]
        for s, r in zip(systems, rho, strict=True)
        for sg in (-1.0, 1.0)
    )
    assert worst < 0.0
    # and it is not slack by a factor: at a tenth of the gain the same matrices fail
    too_low = _theorem1_unrescaled(cert, systems[0], -1.0, 1.0, 0.1 * res.gamma, 0.1, 0.25, 0.75)
    assert np.linalg.eigvalsh(too_low)[-1] > 0.0
