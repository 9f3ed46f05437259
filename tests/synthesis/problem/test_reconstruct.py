"""Reconstruction: the rebuilt closed loop satisfies the analysis inequality at the synthesis nodes,
controllers are continuous in ρ (one state coordinate system), node tables match controller_at."""

from __future__ import annotations

import numpy as np
import pytest

from pressor.synthesis.families.theorem3 import lmi
from pressor.synthesis.families.theorem3.synthesize import synthesize
from pressor.synthesis.problem.config_toml import load_config, theorem3_config_path
from pressor.synthesis.problem.reconstruct import controller_at, scaling_of
from research.synthesis_forms import theorem3_certificate


@pytest.fixture(scope="module")
def design():
    cfg = load_config(theorem3_config_path()).with_grid((2, 2, 2))
    res = synthesize(cfg)
    assert res.artifact is not None
    return cfg, res.artifact


def _to_scaled(c, sc) -> dict[str, np.ndarray]:
    """Physical controller -> scaled-time controller (inverse of unscale_controller)."""
    ts = sc.time_s
    return {
        "Ak": c.Ak * ts,
        "Adk": c.Adk * ts,
        "Bk": c.Bk * sc.sy[None, :] * ts,
        "Ck": c.Ck,
        "Cdk": c.Cdk,
        "Dk": c.Dk * sc.sy[None, :],
    }


def test_reconstructed_closed_loop_satisfies_the_analysis_lmi_at_every_node(design):
    cfg, art = design
    prob = lmi.make_problem(cfg)
    sc = scaling_of(art)
    for g, rho in enumerate(prob.rho):
        ctrl = _to_scaled(controller_at(art, rho), sc)
        F = theorem3_certificate.closed_loop_analysis(prob, art.coefficients, ctrl, g, art.gamma)
        worst = np.linalg.eigvalsh(F).max()
        assert worst < 0.0, f"node {rho}: max eigenvalue {worst}"


def test_a_wrong_controller_fails_the_same_analysis_check(design):
    # the check must be able to fail: flip the sign of the controller's output gain
    cfg, art = design
    prob = lmi.make_problem(cfg)
    sc = scaling_of(art)
    ctrl = _to_scaled(controller_at(art, prob.rho[0]), sc)
    ctrl["Ck"] = -ctrl["Ck"] * 10.0
    ctrl["Dk"] = -ctrl["Dk"] * 10.0
    F = theorem3_certificate.closed_loop_analysis(prob, art.coefficients, ctrl, 0, art.gamma)
    assert np.linalg.eigvalsh(F).max() > 0.0


def test_node_table_equals_controller_at_the_node(design):
    _, art = design
    grid = art.grid
    for i, j, k in [(0, 0, 0), (1, 0, 1), (1, 1, 1)]:
        c = controller_at(art, (grid[0][i], grid[1][j], grid[2][k]))
        for name in ("Ak", "Adk", "Bk", "Ck", "Cdk", "Dk"):
            np.testing.assert_allclose(
                getattr(c, name), art.nodes[name][i, j, k], rtol=1e-12, atol=1e-14
            )


def test_controller_is_continuous_along_a_path_between_neighbouring_nodes(design):
    _, art = design
    box = art.box
    a, b = box[:, 0], box[:, 1]
    path = [a + t * (b - a) for t in np.linspace(0.0, 1.0, 401)]
    mats = [
        np.concatenate(
            [getattr(controller_at(art, r), n).ravel() for n in ("Ak", "Bk", "Ck", "Dk")]
        )
        for r in path
    ]
    mats = np.array(mats)
    steps = np.abs(np.diff(mats, axis=0)).max(axis=0)
    span = np.abs(mats).max(axis=0) + 1e-12
    # 400 steps across the box: every entry moves by a small fraction of its size per step
    assert np.all(steps / span < 0.05)


def test_rho_outside_the_box_is_rejected_not_extrapolated(design):
    _, art = design
    with pytest.raises(ValueError, match="outside the design box"):
        controller_at(art, (art.box[0, 1] * 1.5, 150.0, 40.0))
    with pytest.raises(ValueError):
        controller_at(art, (float("nan"), 150.0, 40.0))


def _nominal_step(
    c, omega: float, lam: float, K=0.55, T=150.0, tau=40.0, r=20.0, tf=3000.0, dt=0.1
):
    """Closed loop in physical time (s): exact step of the undelayed part, delayed terms held
    over one step (delay buffer). State [ΔMAP, u, x_e, x_k]; returns ΔMAP (mmHg)."""
    from scipy.linalg import expm

    a0, ad, br = np.zeros((6, 6)), np.zeros((6, 6)), np.zeros(6)
    cy, dr = np.array([[-1.0, 0, 0], [0, 0, 1.0]]), np.array([1.0, 0.0])
    a0[0, 0], ad[0, 1] = -1.0 / T, K / T
    a0[2, 0], br[2] = -1.0, 1.0
    a0[1, 1] = -lam
    a0[1, :3] += omega * (c.Dk @ cy)[0]
    a0[1, 3:] += omega * c.Ck[0]
    ad[1, 3:] += omega * c.Cdk[0]
    br[1] += omega * (c.Dk @ dr)[0]
    a0[3:, :3], a0[3:, 3:], ad[3:, 3:], br[3:] = c.Bk @ cy, c.Ak, c.Adk, c.Bk @ dr
    m = np.zeros((13, 13))
    m[:6, :6], m[:6, 6:12], m[:6, 12] = a0, ad, br * r
    e = expm(m * dt)
    phi, gd, gr = e[:6, :6], e[:6, 6:12], e[:6, 12]
    d, n = int(round(tau / dt)), int(tf / dt)
    s = np.zeros((n + 1, 6))
    for k in range(n):
        s[k + 1] = phi @ s[k] + (gd @ s[k - d] if k >= d else 0.0) + gr
    return s[:, 0]


def test_physical_controller_tracks_a_step_on_the_nominal_plant_in_seconds(design):
    # units end to end: plant in s, controller_at in s -> MAP reaches the 20 mmHg target
    _, art = design
    c = controller_at(art, (0.55, 150.0, 40.0))
    x = _nominal_step(c, art.omega, art.lambda_)
    assert abs(x[-1] - 20.0) < 0.2
    assert np.abs(x[-1000:] - 20.0).max() < 0.4  # settled over the last 100 s
