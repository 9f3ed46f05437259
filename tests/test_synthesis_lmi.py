"""The batched Theorem-3 LMIs: exact sparse map, same matrices as the naive per-point build, a real
tiny solve whose solution satisfies every LMI."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from synthesis import lmi, lmi_certificate, lmi_naive, lmi_solve
from synthesis.config_toml import load_config


def _cfg(grid=(2, 2, 2), **solver):
    cfg = load_config().with_grid(grid)
    return replace(cfg, solver=replace(cfg.solver, **solver)) if solver else cfg


@pytest.mark.parametrize("mode", ["bound", "vertices"])
def test_sparse_affine_map_reproduces_the_lmi_exactly(mode):
    prob = lmi.make_problem(_cfg(rate_terms=mode))
    x = np.random.default_rng(1).normal(size=prob.layout.nvar)
    A, b, shape = lmi.affine_map(prob, lmi.synthesis_lmi)
    direct = lmi.synthesis_lmi(prob, prob.layout.unpack(x[None, :]))[0]
    np.testing.assert_allclose((A @ x + b).reshape(shape), direct, rtol=1e-12, atol=1e-10)


@pytest.mark.parametrize("mode", ["bound", "vertices"])
def test_batched_build_equals_the_naive_per_point_build(mode):
    prob = lmi.make_problem(_cfg(rate_terms=mode))
    x = np.random.default_rng(2).normal(size=prob.layout.nvar)
    nv = lmi_naive.NaiveVariables(prob.layout)
    nv.set_from(x)
    fs, ps = lmi_naive.naive_lmis(prob, nv)
    batched = lmi.synthesis_lmi(prob, prob.layout.unpack(x[None, :]))[0]
    batched = batched.reshape(-1, *batched.shape[-2:])
    np.testing.assert_allclose(np.array([f.value for f in fs]), batched, rtol=1e-12, atol=1e-10)
    assert len(ps) == lmi.positivity(prob, prob.layout.unpack(x[None, :])).shape[1]


def test_vertex_mode_has_eight_lmis_per_node_and_bound_mode_one():
    assert lmi.make_problem(_cfg(rate_terms="vertices")).vertices.shape == (8, 3)
    p = lmi.make_problem(_cfg(rate_terms="bound"))
    A, b, shape = lmi.affine_map(p, lmi.synthesis_lmi)
    assert shape[:3] == (8, 1, 23)  # 8 nodes of a 2x2x2 grid, one LMI each


def test_lmi_is_symmetric():
    prob = lmi.make_problem(_cfg())
    x = np.random.default_rng(3).normal(size=prob.layout.nvar)
    F = lmi.synthesis_lmi(prob, prob.layout.unpack(x[None, :]))
    np.testing.assert_array_equal(F, np.swapaxes(F, -1, -2))


def test_layout_pack_inverts_unpack():
    lay = lmi.make_problem(_cfg()).layout
    x = np.random.default_rng(4).normal(size=lay.nvar)
    vals = {k: v[0] for k, v in lay.unpack(x[None, :]).items()}
    np.testing.assert_array_equal(lay.pack(vals), x)


def test_tiny_solve_is_optimal_and_every_lmi_holds_at_the_solution():
    prob = lmi.make_problem(_cfg())
    res = lmi_solve.solve(prob)
    assert res.status == "optimal"
    assert np.isfinite(res.gamma) and res.gamma > 0
    worst_lmi, least_pos = lmi.max_eig(prob, res.x)
    assert worst_lmi < 0.0 and least_pos > 0.0


def test_rate_bound_mode_implies_every_rate_vertex():
    # solve in "bound" mode, then check the paper's 8-vertex LMIs with the same variables
    cfg = _cfg()
    prob = lmi.make_problem(cfg)
    res = lmi_solve.solve(prob)
    vprob = lmi.make_problem(replace(cfg, solver=replace(cfg.solver, rate_terms="vertices")))
    vals = prob.layout.unpack(res.x[None, :])
    vals.pop("Z")
    F = lmi.synthesis_lmi(vprob, vals)
    assert F.shape[2] == 8
    assert np.linalg.eigvalsh(F).max() < 0.0


def test_naive_and_batched_formulations_reach_the_same_gamma():
    prob = lmi.make_problem(_cfg())
    batched = lmi_solve.solve(prob)
    naive = lmi_naive.solve_naive(prob)
    assert batched.status == "optimal" and naive.status == "optimal"
    assert abs(naive.gamma - batched.gamma) <= 1e-3 * batched.gamma


def test_certificate_margins_are_negative_at_the_nodes_and_finite_off_grid():
    # Y constant (xy_dependence="x"): the synthesis certificate with the reconstructed controller
    # holds at every node; off the nodes it is only evaluated (a 2x2x2 grid does not cover the box)
    from synthesis.synthesize import synthesize

    cfg = _cfg(xy_dependence="x")
    art = synthesize(cfg).artifact
    nodes = lmi.make_problem(cfg).rho
    assert np.all(lmi_certificate.certificate_margins(art, nodes) < 0.0)
    off = lmi_certificate.certificate_margins(art, art.box.mean(axis=1)[None, :])
    assert off.shape == (1,) and np.isfinite(off[0])
