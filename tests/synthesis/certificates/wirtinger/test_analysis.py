"""The Wirtinger-based analysis LMI: valid bounds, tighter than Jensen's, and it certifies a Smith loop."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from pressor.synthesis.certificates.interface import AnalysisResult
from pressor.synthesis.certificates.jensen.analysis import analyse
from pressor.synthesis.certificates.wirtinger.analysis import analyse_wirtinger
from pressor.synthesis.families.smith.law import SmithLPV
from pressor.synthesis.problem.closed_loop import DelaySystem, close_loop
from pressor.synthesis.problem.config_toml import parse_config
from pressor.synthesis.problem.model import plant_at


def _scalar(a: float, ad: float, tau: float) -> DelaySystem:
    one = np.ones((1, 1))
    return DelaySystem(a * one, ad * one, one, one, 0 * one, 0 * one, tau)


def _single(fn: Callable[..., AnalysisResult], system: DelaySystem, **kw: float) -> AnalysisResult:
    zero = np.zeros(1)
    return fn([system], np.zeros((1, 1)), zero, zero, system.tau, p_dependence="constant", **kw)


def _hinf(system: DelaySystem) -> float:
    """Exact frozen H-infinity norm by a frequency sweep (independent of any LMI)."""
    best = 0.0
    for w in np.concatenate([[1e-9], np.logspace(-6, 1, 3000)]):
        e = np.exp(-1j * w * system.tau)
        res = np.linalg.solve(1j * w * np.eye(system.n) - system.A - system.Ad * e, system.B)
        g = (system.C + system.Cd * e) @ res + system.D
        best = max(best, float(np.linalg.svd(g, compute_uv=False)[0]))
    return best


def test_gain_bound_is_valid_and_tight_on_a_scalar_delay_system() -> None:
    # x' = -x + 0.1 x(t - 1) + w, z = x: H-infinity norm is the DC gain 1 / 0.9
    res = _single(analyse_wirtinger, _scalar(-1.0, 0.1, 1.0))
    assert res.certified
    assert 1.0 / 0.9 * (1 - 1e-6) <= res.gamma <= 1.0 / 0.9 * 1.001


def test_pure_delayed_feedback_certified_beyond_jensen_but_not_past_pi_over_2() -> None:
    # x' = -x(t - tau) is stable iff tau < pi/2 = 1.5708; Jensen stops below 1.5, Wirtinger at 1.5
    assert not _single(analyse, _scalar(0.0, -1.0, 1.5)).certified
    assert _single(analyse_wirtinger, _scalar(0.0, -1.0, 1.5)).certified
    assert not _single(analyse_wirtinger, _scalar(0.0, -1.0, 1.6)).certified


def test_smith_loop_gain_bound_is_its_exact_norm_where_jensen_doubles_it() -> None:
    rho = (0.55, 150.0, 40.0)
    model = parse_config({}).model
    loop = close_loop(plant_at(rho, model), SmithLPV(1.5).at(rho), rho[2])
    exact = _hinf(loop)
    wirt = _single(analyse_wirtinger, loop, time_scale_s=40.0)
    jensen = _single(analyse, loop, time_scale_s=40.0, backoff=0.0)
    assert wirt.certified
    assert exact * (1 - 1e-3) <= wirt.gamma <= exact * 1.02
    assert jensen.gamma is None or jensen.gamma > 1.5 * wirt.gamma


def test_certificate_has_the_augmented_lyapunov_matrix() -> None:
    res = _single(analyse_wirtinger, _scalar(-1.0, 0.1, 1.0))
    cert = res.certificate
    assert cert is not None and cert["P"].shape == (1, 2, 2)
    assert np.linalg.eigvalsh(cert["P"][0])[0] > 0 and cert["S"][0, 0] > 0 and cert["R"][0, 0] > 0


def test_zero_delay_is_rejected() -> None:
    with pytest.raises(ValueError, match="delay"):
        _single(analyse_wirtinger, _scalar(-1.0, 0.1, 0.0))


def _delayed_feedback_grid(k0: float, k1: float) -> tuple[list[DelaySystem], np.ndarray, tuple]:
    """x' = -k(rho1) x(t - tau(rho2)) + w on a 3 x 3 grid, k = k0 + k1 rho1, tau = 0.9 + 0.1 rho2 s,
    both parameters moving (4 rate vertices): stable at every frozen point iff k tau < pi/2."""
    r = np.linspace(-1.0, 1.0, 3)
    rho = np.array([(r1, r2) for r1 in r for r2 in r])
    systems = [_scalar(0.0, -(k0 + k1 * r1), 0.9 + 0.1 * r2) for r1, r2 in rho]
    return systems, rho, (np.array([0.05, 0.05]), np.array([0.0, 0.1]), 1.0)


@pytest.mark.parametrize(("k0", "k1", "stable"), [(1.0, 0.2, True), (1.3, 0.4, False)])
def test_working_set_gives_the_verdict_of_the_all_points_solve(
    k0: float, k1: float, stable: bool
) -> None:
    # k tau <= 1.2 everywhere (certifiable); k tau = 1.7 > pi/2 at one corner (unstable there)
    systems, rho, (rate, dtau, tau_max) = _delayed_feedback_grid(k0, k1)
    kw = dict(p_dependence="affine", gamma_cap=1e3)
    full = analyse_wirtinger(systems, rho, rate, dtau, tau_max, **kw)
    fast = analyse_wirtinger(systems, rho, rate, dtau, tau_max, working_set=2, **kw)
    assert full.certified == fast.certified == stable
    assert fast.n_lmis == full.n_lmis == 9 * 4  # every point, every rate vertex re-checked
    assert fast.margins.shape == fast.p_min_eig.shape == (9,)
    if stable:
        assert np.all(fast.margins > 0) and np.all(fast.p_min_eig > 0)
    else:
        assert np.min(fast.margins) <= 0


def test_working_set_adds_a_point_it_never_imposed_that_fails_the_recheck() -> None:
    # x' = a x + 0.2 x(t - 0.5) + w, z = x: DC gain 1/(-a - 0.2) is 1.25 at a = -1 and 10 at the
    # one weak point a = -0.3 (rho = 1, not in the first working set of one centre point), so
    # the centre-only optimum (gamma ~ 1.25) must fail the re-check there and the set must grow
    rho = np.linspace(-1.0, 1.0, 5)[:, None]
    systems = [_scalar(-0.3 if r == 1.0 else -1.0, 0.2, 0.5) for r in rho[:, 0]]
    args = (systems, rho, np.zeros(1), np.zeros(1), 0.5)
    lines: list[str] = []
    fast = analyse_wirtinger(*args, p_dependence="constant", working_set=1, progress=lines.append)
    full = analyse_wirtinger(*args, p_dependence="constant")
    assert fast.certified and full.certified
    assert any("failed the re-check" in note for note in fast.notes)
    assert fast.gamma >= 10.0 * (1 - 1e-5)  # the exact gain at the point first left out
    assert fast.gamma == pytest.approx(full.gamma, rel=1e-3)
    iters = [ln for ln in lines if " iter " in ln]  # the solver reports every iteration
    assert len(iters) >= 3 and all("gap" in ln and "pres" in ln for ln in iters)


def test_gamma_cap_infeasible_at_the_imposed_points_stops_without_adding_points() -> None:
    # every point has the DC gain 1/(1 - 0.2) = 1.25 > cap 1.2: the imposed centre point fails,
    # so no larger set can pass and the verdict is the all-points one without another solve
    rho = np.linspace(-1.0, 1.0, 5)[:, None]
    systems = [_scalar(-1.0, 0.2, 0.5) for _ in rho[:, 0]]
    args = (systems, rho, np.zeros(1), np.zeros(1), 0.5)
    fast = analyse_wirtinger(*args, p_dependence="constant", gamma_cap=1.2, working_set=1)
    full = analyse_wirtinger(*args, p_dependence="constant", gamma_cap=1.2)
    assert not fast.certified and not full.certified
    assert any("no points added" in note for note in fast.notes)
    assert "working set: LMI imposed at 1 of 5 points" in fast.notes
    assert fast.margins.shape == (5,) and np.all(fast.margins < 0)


def _two_moving(stable: bool) -> tuple[list[DelaySystem], np.ndarray, tuple]:
    """The delayed-feedback grid with a damping term so gamma is finite: x' = -0.2 x - k x(t - tau) + w."""
    systems, rho, args = (
        _delayed_feedback_grid(1.0, 0.2) if stable else _delayed_feedback_grid(1.3, 0.4)
    )
    damped = [DelaySystem(q.A - 0.2, q.Ad, q.B, q.C, q.Cd, q.D, q.tau) for q in systems]
    return damped, rho, args


def test_rate_bound_form_certifies_every_vertex_and_is_never_below_the_vertex_bound() -> None:
    # one LMI per point instead of 4 vertex LMIs: sufficient, so its gamma is >= the vertex one,
    # and the re-check of every vertex at its solution passes
    systems, rho, (rate, dtau, tau_max) = _two_moving(stable=True)
    kw = dict(p_dependence="affine")
    vertex = analyse_wirtinger(systems, rho, rate, dtau, tau_max, **kw)
    bound = analyse_wirtinger(systems, rho, rate, dtau, tau_max, rate_form="bound", **kw)
    assert vertex.certified and bound.certified
    assert bound.n_lmis == vertex.n_lmis == 9 * 4 and np.all(bound.margins > 0)
    assert vertex.gamma * (1 - 1e-4) <= bound.gamma <= vertex.gamma * 1.01


def test_rate_bound_form_does_not_certify_an_unstable_corner() -> None:
    systems, rho, (rate, dtau, tau_max) = _two_moving(stable=False)
    res = analyse_wirtinger(
        systems, rho, rate, dtau, tau_max, p_dependence="affine", rate_form="bound", gamma_cap=1e3
    )
    assert not res.certified and np.min(res.margins) <= 0


def test_per_point_coupling_is_the_same_problem_as_the_dense_one() -> None:
    systems, rho, (rate, dtau, tau_max) = _two_moving(stable=True)
    for form in ("vertex", "bound"):
        kw = dict(p_dependence="quadratic", rate_form=form)
        dense = analyse_wirtinger(systems, rho, rate, dtau, tau_max, **kw)
        split = analyse_wirtinger(systems, rho, rate, dtau, tau_max, coupling="per_point", **kw)
        assert dense.certified and split.certified
        assert split.gamma == pytest.approx(dense.gamma, rel=1e-4)


def test_p_independent_of_a_parameter_drops_its_rate_vertices_and_costs_gamma() -> None:
    # P in rho_2 (the delay parameter) only: rho_1 no longer moves anything, 2 vertices per point
    systems, rho, (rate, dtau, tau_max) = _two_moving(stable=True)
    full = analyse_wirtinger(systems, rho, rate, dtau, tau_max, p_dependence="affine")
    part = analyse_wirtinger(systems, rho, rate, dtau, tau_max, p_dependence="affine", p_params=[1])
    assert part.certified and part.n_lmis == 9 * 2
    assert part.gamma >= full.gamma * (1 - 1e-4)
    with pytest.raises(ValueError, match="p_params"):
        analyse_wirtinger(systems, rho, rate, dtau, tau_max, p_params=[2])


def test_rate_bound_form_certifies_the_smith_loop_on_a_grid_above_every_frozen_norm() -> None:
    # the scheduled Smith predictor (loop gain 2) on the 2 x 2 x 2 corners of the shipped box,
    # every rate moving: the one-LMI form certifies it, and its bound can never undercut the
    # exact H-infinity norm of any frozen point (what physics allows)
    model = parse_config({}).model
    box = np.array([[0.25, 1.0], [100.0, 200.0], [10.0, 45.0]])
    half = 0.5 * (box[:, 1] - box[:, 0])
    rho_hat = np.array([(a, b, c) for a in (-1.0, 1.0) for b in (-1.0, 1.0) for c in (-1.0, 1.0)])
    rhos = 0.5 * (box[:, 0] + box[:, 1]) + rho_hat * half
    loops = [close_loop(plant_at(r, model), SmithLPV(2.0).at(r), r[2]) for r in rhos]
    res = analyse_wirtinger(
        loops,
        rho_hat,
        np.array([2e-4, 0.06, 0.1]) / half,
        np.array([0.0, 0.0, half[2]]),
        45.0,
        p_dependence="affine",
        time_scale_s=45.0,
        rate_form="bound",
    )
    assert res.certified and res.n_lmis == 8 * 8
    assert res.gamma >= max(_hinf(q) for q in loops) * (1 - 1e-3)
