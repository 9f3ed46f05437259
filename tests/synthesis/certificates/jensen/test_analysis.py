"""The delay-dependent analysis LMI certifies stable delay loops and refuses unstable ones."""

from __future__ import annotations

import numpy as np
import pytest

from pressor.synthesis.certificates.jensen.analysis import analyse
from pressor.synthesis.certificates.state_transform import conditioning_transform
from pressor.synthesis.problem.closed_loop import DelaySystem
from pressor.synthesis.verification.pi_baseline import PIBaseline


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


def _pi_loops(kp: float) -> tuple[list, np.ndarray, tuple]:
    """PI baseline loops on a 2 x 2 x 3 grid of the real plant (K, T, tau), rho_hat in [-1, 1]."""
    ks, ts, taus = (0.45, 0.65), (120.0, 180.0), (20.0, 30.0, 40.0)
    pts = [(k, t, tau) for k in ks for t in ts for tau in taus]
    systems = [PIBaseline(kp=kp).closed_loop(k, t, tau) for k, t, tau in pts]
    lo, hi = np.array([0.45, 120.0, 20.0]), np.array([0.65, 180.0, 40.0])
    rho = (np.array(pts) - (lo + hi) / 2) / ((hi - lo) / 2)
    half = (hi - lo) / 2
    args = (np.array([1e-4, 0.03, 0.05]) / half, np.array([0.0, 0.0, half[2]]), 40.0)
    return systems, rho, args


@pytest.mark.parametrize("rate_bound", [False, True])
@pytest.mark.parametrize("kp", [3.0, 15.0])
def test_working_set_gives_the_verdict_of_the_all_points_solve_on_pi_loops(
    kp: float, rate_bound: bool
) -> None:
    # kp = 3: the shipped PI, certified; kp = 15: past its delay margin, not certifiable
    systems, rho, (rate, dtau, tau_max) = _pi_loops(kp)
    kw = dict(p_dependence="quadratic", time_scale_s=40.0, gamma_cap=1e3)
    full = analyse(systems, rho, rate, dtau, tau_max, **kw)
    fast = analyse(systems, rho, rate, dtau, tau_max, working_set=2, rate_bound=rate_bound, **kw)
    assert full.certified == fast.certified == (kp == 3.0)
    assert fast.n_lmis == full.n_lmis == 12 * 8  # every point, every rate vertex re-checked
    if fast.certified:
        assert np.all(fast.margins > 0) and np.all(fast.p_min_eig > 0)


def test_working_set_grows_until_a_point_it_never_imposed_passes_the_recheck() -> None:
    # x' = a x + 0.2 x(t - 0.5) + w, z = x: DC gain 1/(-a - 0.2) is 1.25 at a = -1 and 10 at the
    # one weak point a = -0.3 (rho = 1, not in the first working set of one centre point), so
    # the centre-only optimum (gamma ~ 1.25) must fail the re-check there and the set must grow
    rho = np.linspace(-1.0, 1.0, 5)[:, None]
    systems = [_scalar(-0.3 if r == 1.0 else -1.0, 0.2, 0.5) for r in rho[:, 0]]
    args = (systems, rho, np.zeros(1), np.zeros(1), 0.5)
    fast = analyse(*args, p_dependence="constant", backoff=0.0, working_set=1)
    full = analyse(*args, p_dependence="constant", backoff=0.0)
    assert fast.certified and full.certified
    assert any("failed the re-check" in note for note in fast.notes)
    assert fast.gamma >= 10.0 * (1 - 1e-6)  # the exact gain at the point first left out
    assert fast.gamma == pytest.approx(full.gamma, rel=1e-3)


def test_solver_progress_reports_iterations_and_residuals() -> None:
    lines: list[str] = []
    res = _single(_scalar(-1.0, 0.1, 1.0), backoff=0.0, progress=lines.append)
    assert res.certified
    iters = [ln for ln in lines if " iter " in ln]
    assert len(iters) >= 3
    assert all("gap" in ln and "pres" in ln and "dres" in ln for ln in iters)


def test_rate_bound_form_too_conservative_falls_back_to_the_vertex_form_and_certifies() -> None:
    # x' = -(1 + 0.5 rho) x + 0.45 x(t - tau(rho)), tau = 0.5 + 0.45 rho moving at 0.45 s/s: the
    # bound form charges the worst dP/dt and the worst dtau/dt at once (they come from the same
    # rho-dot, opposite signs help each other at the vertices) and fails; the vertices certify
    rho = np.linspace(-1.0, 1.0, 3)[:, None]
    systems = [_scalar(-(1.0 + 0.5 * r), 0.45, 0.5 + 0.45 * r) for r in rho[:, 0]]
    args = (systems, rho, np.array([1.0]), np.array([0.45]), 0.95)
    kw = dict(p_dependence="quadratic", gamma_cap=50.0)
    full = analyse(*args, **kw)
    fast = analyse(*args, working_set=1, rate_bound=True, **kw)
    assert full.certified and fast.certified
    assert any("rate-bound form not certified" in note for note in fast.notes)
    assert np.all(fast.margins > 0) and fast.n_lmis == 3 * 2


@pytest.mark.parametrize("p_dependence", ["constant", "affine"])
def test_rate_bound_form_without_or_with_p_slopes_matches_the_vertex_verdict(
    p_dependence: str,
) -> None:
    # constant P: no dP/dt, no slack at all, only the worst dtau/dt; affine P: one slack per point
    rho = np.linspace(-1.0, 1.0, 3)[:, None]
    systems = [_scalar(-1.0 - 0.5 * r, 0.2, 0.5 + 0.25 * r) for r in rho[:, 0]]
    args = (systems, rho, np.array([0.4]), np.array([0.25]), 0.75)
    kw = dict(p_dependence=p_dependence, gamma_cap=10.0)
    fast = analyse(*args, working_set=1, rate_bound=True, **kw)
    assert fast.certified and analyse(*args, **kw).certified
    assert any("rate-bound form, re-checked" in note for note in fast.notes)
