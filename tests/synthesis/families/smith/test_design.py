"""The shipped family's design: the shipped law reproduced, its certificate re-checked without a
solve."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pressor.synthesis.artifact import default_artifact_path, load_artifact
from pressor.synthesis.families.smith.design import design_smith, recheck_smith_artifact
from pressor.synthesis.problem.config_toml import load_config


@pytest.fixture(scope="module")
def shipped():
    return load_artifact(default_artifact_path())


def test_the_shipped_certificate_passes_the_floating_point_recheck_on_this_machine(shipped):
    certified, margins = recheck_smith_artifact(shipped)
    assert certified
    assert margins.shape == (8,) and np.all(margins > 5e-4)  # the design's strictness is 1e-3


def test_a_certificate_claiming_a_smaller_gain_bound_fails_the_recheck(shipped):
    claimed = replace(shipped, metadata={**shipped.metadata, "gamma": 0.5 * shipped.gamma})
    certified, margins = recheck_smith_artifact(claimed)
    assert not certified and np.min(margins) < 0


def test_a_tampered_certificate_fails_the_recheck(shipped):
    coefs = {**shipped.coefficients, "R": -shipped.coefficients["R"]}
    certified, _ = recheck_smith_artifact(replace(shipped, coefficients=coefs))
    assert not certified


def test_synth_reproduces_the_shipped_law_exactly_with_a_certificate_that_rechecks(shipped):
    # the law is closed form, so its nodes are the same bits on every machine; the certificate
    # (P, S, R) is a solver's answer and may differ across CPUs: it is re-checked, not compared
    art = design_smith(load_config())
    assert art.nodes.keys() == shipped.nodes.keys()
    for name, value in shipped.nodes.items():
        np.testing.assert_array_equal(art.nodes[name], value, err_msg=name)
    assert (
        art.family == shipped.family and art.metadata["reference"] == shipped.metadata["reference"]
    )
    certified, margins = recheck_smith_artifact(art)
    assert certified and np.all(margins > 5e-4)
    assert abs(art.gamma - shipped.gamma) < 0.01 * shipped.gamma
