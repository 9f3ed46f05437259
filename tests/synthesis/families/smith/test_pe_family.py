"""The "smith-pe" family: the shipped law on a 200 s delay box, certified in prediction-error
coordinates, through the real design stage and ``pressor verify``'s checks."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pressor.synthesis.families.registry import SynthRequest, family_named
from pressor.synthesis.families.smith.law import SmithLPV
from pressor.synthesis.problem.config_toml import load_config
from pressor.synthesis.verification.verify import verify_artifact

DESIGN = "synthesis/data/wide_delay_design.toml"


@pytest.fixture(scope="module")
def designed():
    cfg = load_config(DESIGN)
    done = family_named("smith-pe").design(cfg, SynthRequest(), lambda _msg: None)
    return cfg, done


def test_the_200_s_box_is_certified_at_the_designs_loop_gain(designed):
    _, done = designed
    assert done.artifact is not None, done.failure
    assert done.artifact.family.structure == "smith-pe"
    assert np.isfinite(done.artifact.gamma)
    assert done.artifact.coefficients["P"].shape == (3, 8, 8)


def test_its_nodes_are_the_shipped_law(designed):
    cfg, done = designed
    art = done.artifact
    law = SmithLPV(cfg.controller.loop_gain, cfg.model.omega, cfg.model.lambda_)
    k, t, tau = (g[-1] for g in art.grid)
    at = law.at((k, t, tau))
    np.testing.assert_array_equal(art.nodes["Adk"][-1, -1, -1], at.Adk)
    np.testing.assert_array_equal(art.nodes["Ck"][-1, -1, -1], at.Ck)


@pytest.mark.slow  # 15 s: the denser grid's analysis, the rightmost roots and the step
def test_verify_passes_every_check_on_the_denser_grid(designed):
    _, done = designed
    report = verify_artifact(done.artifact)
    assert report.passed
    assert report.analysis_lmi["certified"]


def test_the_same_box_at_the_shipped_rates_is_refused():
    cfg = load_config(DESIGN)
    cfg_fast = replace(cfg, model=replace(cfg.model, rate_bounds=np.array([6e-4, 0.06, 0.1])))
    done = family_named("smith-pe").design(cfg_fast, SynthRequest(), lambda _msg: None)
    assert done.artifact is None and "not certified" in (done.failure or "")
