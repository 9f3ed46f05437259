"""A real tiny solve of the batched synthesis SDP: optimal, every LMI holds at the solution, the
rate-bound form implies every rate vertex and the naive formulation reaches the same gamma."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pressor.synthesis.families.theorem3 import lmi, lmi_solve
from pressor.synthesis.problem.config_toml import load_config, theorem3_config_path
from research.synthesis_forms import naive_lmi


def _cfg():
    return load_config(theorem3_config_path()).with_grid((2, 2, 2))


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


# slow: the naive formulation is a research ablation (research.synthesis_forms), not the shipped path
@pytest.mark.slow
def test_naive_and_batched_formulations_reach_the_same_gamma():
    prob = lmi.make_problem(_cfg())
    batched = lmi_solve.solve(prob)
    naive = naive_lmi.solve_naive(prob)
    assert batched.status == "optimal" and naive.status == "optimal"
    assert abs(naive.gamma - batched.gamma) <= 1e-3 * batched.gamma
