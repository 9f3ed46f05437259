"""Frequency-shaped performance weights: plant rows equal the documented W_e, W_u; weight states
have the documented poles; bad weights are rejected; a real solve pays γ for bandwidth."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pressor.synthesis.artifact import load_artifact, save_artifact
from pressor.synthesis.families.theorem3 import lmi, lmi_solve
from pressor.synthesis.families.theorem3.synthesize import synthesize
from pressor.synthesis.problem.config import ConfigError
from pressor.synthesis.problem.config_toml import load_config, parse_config
from pressor.synthesis.problem.model import dims, plant_at
from pressor.synthesis.problem.reconstruct import controller_at

RHO = (0.55, 150.0, 40.0)
W = np.array([1e-4, 3e-3, 0.02, 0.3])  # rad/s


def _shaped(**weights: float) -> dict:
    return {"weights": {"performance": "shaped", **weights}}


def _freq(p, s: complex, out_row: int, in_col: np.ndarray, in_u: bool = False) -> complex:
    """Frozen transfer (with the delay) from w column / u_a to one z row."""
    n = p.A.shape[0]
    e = np.exp(-s * RHO[2])
    b = p.B2[:, 0] if in_u else p.B1[:, in_col]
    d = p.D12[out_row, 0] if in_u else p.D11[out_row, in_col]
    x = np.linalg.solve(s * np.eye(n) - p.A - p.Ad * e, b)
    return complex((p.C1[out_row] + p.C1d[out_row] * e) @ x + d)


@pytest.mark.parametrize("a_dc", [0.0, 0.01])
def test_tracking_row_is_the_low_pass_weight_over_root_two(a_dc):
    wb, m = 0.004, 2.5
    cfg = parse_config(_shaped(e_crossover_rad_s=wb, e_peak=m, e_dc=a_dc)).model
    p = plant_at(RHO, cfg)
    for w in W:
        s = 1j * w
        expected = (s / m + wb) / (s + wb * a_dc) / np.sqrt(2.0)
        # with u_a = 0 the MAP stays 0, so e = r
        assert _freq(p, s, 0, 0) == pytest.approx(expected, rel=1e-9)
        assert _freq(p, s, 0, 1) == pytest.approx(-expected, rel=1e-9)  # e = r - MAP - d_o


@pytest.mark.parametrize("eps_u", [0.0, 0.5])
def test_infusion_row_is_the_high_pass_weight_on_the_filtered_command(eps_u):
    wu, mu = 0.03, 12.0
    cfg = parse_config(_shaped(u_crossover_rad_s=wu, u_dc=mu, u_hf=eps_u)).model
    p = plant_at(RHO, cfg)
    for w in W:
        s = 1j * w
        filt = cfg.omega / (s + cfg.lambda_)  # u = Ω/(s + Λ) u_a
        expected = (s + wu / mu) / (eps_u * s + wu) * filt / np.sqrt(2.0)
        assert _freq(p, s, 1, None, in_u=True) == pytest.approx(expected, rel=1e-9)
    assert p.D12[2, 0] == cfg.xi  # ξ u_a stays as the last row


def test_weight_states_are_appended_with_the_documented_poles():
    wb, a_dc, wu, eps_u = 0.004, 0.02, 0.03, 0.5
    cfg = parse_config(_shaped(e_crossover_rad_s=wb, e_dc=a_dc, u_crossover_rad_s=wu, u_hf=eps_u))
    d = dims(cfg.model)
    assert (d.n, d.nz) == (5, 3)
    p = plant_at(RHO, cfg.model)
    assert p.A[3, 3] == pytest.approx(-wb * a_dc)
    assert p.A[4, 4] == pytest.approx(-wu / eps_u)
    # the measurement does not see the weight states: they are performance-only
    np.testing.assert_array_equal(p.C2[:, 3:], 0.0)
    assert dims(parse_config(_shaped()).model).n == 3  # A = 0, ε_u = 0: no new state


def test_shipped_default_keeps_the_integral_output_and_its_metadata():
    cfg = load_config()
    assert cfg.model.shaping is None
    assert "shaping" not in cfg.model.to_dict()
    assert dims(cfg.model).n == 3


@pytest.mark.parametrize(
    ("weights", "field", "allowed"),
    [
        pytest.param({"performance": "fast"}, "weights.performance", "'shaped'", id="mode"),
        pytest.param({"e_peak": 1.0}, "weights.e_peak", "(1, 100]", id="peak-not-above-one"),
        pytest.param({"e_dc": 1.0}, "weights.e_dc", "[0, 1)", id="dc-not-below-one"),
        pytest.param({"e_crossover_rad_s": 0.0}, "weights.e_crossover_rad_s", "(0, 10]", id="wb"),
        pytest.param({"u_dc": 5.0, "u_hf": 5.0}, "weights.u_hf", "u_dc = 5", id="not-high-pass"),
        pytest.param({"u_crossover_rad_s": -1}, "weights.u_crossover_rad_s", "(0, 100]", id="wu"),
    ],
)
def test_bad_weight_is_rejected_naming_file_field_value_and_range(
    tmp_path: Path, weights, field, allowed
):
    p = tmp_path / "d.toml"
    body = "\n".join(f"{k} = {v!r}".replace("'", '"') for k, v in weights.items())
    p.write_text("[weights]\n" + body + "\n")
    with pytest.raises(ConfigError) as exc:
        load_config(p)
    msg = str(exc.value)
    assert str(p) in msg and field in msg and allowed in msg


def _small(table: dict) -> object:
    cfg = parse_config(table).with_grid((2, 2, 2))
    return replace(cfg, lambda2_candidates=(1.0,), lambda3_candidates=(0.5,))


@pytest.mark.slow
def test_a_larger_bandwidth_demand_costs_a_larger_gamma():
    gammas = []
    for wb in (0.002, 0.008):
        res = lmi_solve.solve(lmi.make_problem(_small(_shaped(e_crossover_rad_s=wb))))
        assert res.status == "optimal"
        gammas.append(res.gamma)
    # the demand at low frequency grows 4x; the achievable |S| does not follow it
    assert gammas[1] > 1.5 * gammas[0]


@pytest.mark.slow
def test_weight_states_survive_synthesis_artifact_and_reconstruction(tmp_path: Path):
    cfg = _small(_shaped(e_dc=0.01, u_hf=0.5))
    art = synthesize(cfg).artifact
    assert art is not None
    path = save_artifact(art, tmp_path / "w.npz")
    back = load_artifact(path)
    k = controller_at(back, RHO)
    assert k.Ak.shape == (5, 5) and k.Bk.shape == (5, 2)
    np.testing.assert_array_equal(back.nodes["Ak"], art.nodes["Ak"])
