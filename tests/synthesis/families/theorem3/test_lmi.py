"""The batched Theorem-3 LMIs: exact sparse map, same matrices as the naive per-point build."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pressor.synthesis.families.theorem3 import lmi
from pressor.synthesis.problem.config_toml import load_config
from research.synthesis_forms import naive_lmi


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
    nv = naive_lmi.NaiveVariables(prob.layout)
    nv.set_from(x)
    fs, ps = naive_lmi.naive_lmis(prob, nv)
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
