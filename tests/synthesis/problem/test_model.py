"""The augmented LPV plant: matrices, measurement observability, scaling invariance."""

from __future__ import annotations

import numpy as np

from pressor.synthesis.problem.config_toml import load_config
from pressor.synthesis.problem.model import plant_at, plant_batch
from pressor.synthesis.problem.scaling import Scaling

CFG = load_config().model


def _obsv_rank(A: np.ndarray, C: np.ndarray) -> int:
    n = A.shape[0]
    O = np.vstack([C @ np.linalg.matrix_power(A, k) for k in range(n)])
    return int(np.linalg.matrix_rank(O, tol=1e-9))


def test_nominal_plant_matrices_follow_the_paper():
    p = plant_at((0.55, 150.0, 40.0), CFG)
    assert p.A[0, 0] == -1.0 / 150.0
    assert p.A[1, 1] == -CFG.lambda_
    assert p.A[2, 0] == -1.0
    assert p.Ad[0, 1] == 0.55 / 150.0
    assert p.B2[1, 0] == CFG.omega
    np.testing.assert_array_equal(p.B1[2], [1.0, -1.0, 0.0])
    assert p.C1[0, 2] == CFG.phi and p.D12[1, 0] == CFG.xi


def test_static_gain_from_infusion_to_map_is_K():
    p = plant_at((0.8, 120.0, 20.0), CFG)
    # steady state of the MAP row with the delay removed: 0 = A00 x + Ad01 u
    assert -p.Ad[0, 1] / p.A[0, 0] == 0.8


def test_measuring_e_and_xe_makes_the_integrator_observable_but_printed_c2_does_not():
    p = plant_at((0.55, 150.0, 40.0), CFG)
    a_frozen = p.A + p.Ad  # delay-free frozen system
    assert _obsv_rank(a_frozen, p.C2) == 3
    printed_c2 = np.array([[1.0, 0.0, 0.0]])
    assert _obsv_rank(a_frozen, printed_c2) < 3


def test_xe_channel_carries_the_noise_weight():
    p = plant_at((0.55, 150.0, 40.0), CFG)
    np.testing.assert_array_equal(p.D21, [[1.0, -1.0, 0.0], [0.0, 0.0, CFG.eta_xe]])


def test_scaled_plant_has_the_same_frequency_response_in_scaled_time():
    rho = np.array([[0.4, 180.0, 30.0]])
    sc = Scaling.for_box(CFG.box, 40.0)
    p = {k: v[0] for k, v in plant_batch(rho, CFG).items()}
    q = {k: v[0] for k, v in sc.plant(plant_batch(rho, CFG)).items()}
    s = 0.013j  # rad/s
    tau = rho[0, 2]

    def h(m, s, tau):
        n = m["A"].shape[0]
        a = m["A"] + m["Ad"] * np.exp(-s * tau)
        return m["C2"] @ np.linalg.solve(s * np.eye(n) - a, m["B2"])

    physical = h(p, s, tau)
    scaled = h(q, s * sc.time_s, tau / sc.time_s)
    np.testing.assert_allclose(np.diag(sc.sy) @ scaled, physical, rtol=1e-10)


def test_rho_maps_to_unit_box_and_back():
    sc = Scaling.for_box(CFG.box, 40.0)
    hat = sc.to_hat(CFG.box.T)
    np.testing.assert_allclose(hat, [[-1, -1, -1], [1, 1, 1]])
    np.testing.assert_allclose(sc.from_hat(hat), CFG.box.T)
