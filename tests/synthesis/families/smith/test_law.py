"""The Smith predictor written in the LPV controller class behaves as the delay-free design delayed."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from pressor.synthesis.families.smith.law import SmithLPV
from pressor.synthesis.problem.closed_loop import close_loop
from pressor.synthesis.problem.config_toml import parse_config
from pressor.synthesis.problem.model import plant_at
from pressor.synthesis.verification.delay_stability import rightmost_roots
from pressor.synthesis.verification.step_response import loop_from_closed_loop, simulate_step

MODEL = parse_config({}).model  # the shipped model: omega = lambda = 0.1 1/s


def test_without_delay_it_is_the_pi_kc_e_plus_ki_xe_with_the_lambda_tuning() -> None:
    # K = 0.5, T = 150 s, loop gain 3 -> lambda = 50 s, Kc = T/(K lambda) = 6, Ki = 1/(K lambda) = 0.04
    c = SmithLPV(3.0).at((0.5, 150.0, 0.0))
    np.testing.assert_allclose(c.Dk, [[6.0, 0.04]], rtol=1e-12)
    np.testing.assert_allclose(c.Ck + c.Cdk, np.zeros((1, 2)), atol=1e-12)  # model paths cancel


@pytest.mark.parametrize("rho", [(0.55, 150.0, 40.0), (0.25, 200.0, 45.0)])
def test_step_is_the_delay_free_second_order_loop_delayed_by_tau(
    rho: tuple[float, float, float],
) -> None:
    # with omega = lambda the delay-free loop is 1/(lambda s (10 s + 1)) -> 1/(10 lam s^2 + lam s + 1);
    # a Smith predictor shows it delayed by tau; the trapezoid costs < 0.25 mmHg on a 20 mmHg step
    k, t_s, tau_s = rho
    loop = close_loop(plant_at(rho, MODEL), SmithLPV(3.0).at(rho), tau_s)
    resp = simulate_step(loop_from_closed_loop(loop), 20.0, 1200.0)
    lam = t_s / 3.0
    _, y_free, _ = signal.lsim(([1.0], [10.0 * lam, lam, 1.0]), np.ones_like(resp.t_s), resp.t_s)
    lag = int(round(tau_s / (resp.t_s[1] - resp.t_s[0])))
    expected = np.zeros_like(y_free)
    expected[lag:] = 20.0 * y_free[: len(y_free) - lag]
    assert np.max(np.abs(resp.map_mmhg - expected)) < 0.25
    assert abs(resp.map_mmhg[-1] - 20.0) < 1e-3  # x_e integral action: no steady-state error


def test_frozen_loops_at_the_box_corners_are_exponentially_stable() -> None:
    box = MODEL.box
    for rho in np.stack(np.meshgrid(*box, indexing="ij"), axis=-1).reshape(-1, 3):
        loop = close_loop(plant_at(rho, MODEL), SmithLPV(3.0).at(rho), float(rho[2]))
        assert rightmost_roots(loop.A, loop.Ad, loop.tau, count=3).abscissa < 0.0


@pytest.mark.parametrize("field", ["loop_gain", "omega", "lambda_"])
def test_non_positive_settings_are_rejected_by_name(field: str) -> None:
    kw = {"loop_gain": 3.0, field: 0.0}
    with pytest.raises(ValueError, match=field):
        SmithLPV(**kw)


def test_non_physical_plant_point_is_rejected() -> None:
    with pytest.raises(ValueError, match="K="):
        SmithLPV(3.0).at((0.0, 150.0, 40.0))
    with pytest.raises(ValueError, match="tau="):
        SmithLPV(3.0).at((0.5, 150.0, -1.0))
