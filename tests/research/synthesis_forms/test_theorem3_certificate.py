"""The synthesis certificate evaluated with the reconstructed controller away from the solve."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from pressor.synthesis.families.theorem3 import lmi
from pressor.synthesis.problem.config_toml import load_config, theorem3_config_path
from research.synthesis_forms import theorem3_certificate


def _cfg(**solver):
    cfg = load_config(theorem3_config_path()).with_grid((2, 2, 2))
    return replace(cfg, solver=replace(cfg.solver, **solver))


def test_certificate_margins_are_negative_at_the_nodes_and_finite_off_grid():
    # Y constant (xy_dependence="x"): the synthesis certificate with the reconstructed controller
    # holds at every node; off the nodes it is only evaluated (a 2x2x2 grid does not cover the box)
    from pressor.synthesis.families.theorem3.synthesize import synthesize

    cfg = _cfg(xy_dependence="x")
    art = synthesize(cfg).artifact
    nodes = lmi.make_problem(cfg).rho
    assert np.all(theorem3_certificate.certificate_margins(art, nodes) < 0.0)
    off = theorem3_certificate.certificate_margins(art, art.box.mean(axis=1)[None, :])
    assert off.shape == (1,) and np.isfinite(off[0])
