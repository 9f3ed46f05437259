"""certify_smith options (real Wirtinger solves); the shipped law reproduced, its certificate
re-checked without a solve."""

from __future__ import annotations

import re
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from synthesis.analysis_interface import AnalysisResult
from synthesis.artifact import default_artifact_path, load_artifact
from synthesis.config_toml import load_config
from synthesis.reconstruct import scaling_of
from synthesis.smith_design import (
    certify_smith,
    design_smith,
    nominal_centre,
    recheck_smith_artifact,
    smith_loops,
)
from synthesis.smith_lpv import SmithLPV

K_SCALED_NOTE = "K-scaled coordinates"


@pytest.fixture(scope="module")
def loop_gain_2() -> dict[str, Any]:
    """Loop gain 2 on the shipped model: two points at the ends of the K range (T 150 s, τ 40 s)."""
    art = load_artifact(default_artifact_path())
    model = art.model_config
    law = SmithLPV(2.0, model.omega, model.lambda_)
    k_lo, k_hi = model.box[0]
    points = np.array([[k_lo, 150.0, 40.0], [k_hi, 150.0, 40.0]])
    return {
        "systems": smith_loops(law, model, points),
        "points": points,
        "centre": nominal_centre(law, model),
        "model": model,
        "scaling": scaling_of(art),
    }


def _certify(case: dict[str, Any], **options: Any) -> AnalysisResult:
    return certify_smith(
        case["systems"],
        case["points"],
        case["centre"],
        case["model"],
        case["scaling"],
        p_dependence="affine",
        **options,
    )


@pytest.mark.parametrize(
    ("option", "value", "allowed"),
    [
        ("coordinates", "scaled", "('k_scaled', 'plain')"),
        ("coupling", "sparse", "('dense', 'per_point')"),
        ("rate_form", "edges", "('vertex', 'bound')"),
    ],
)
def test_bad_option_raises_value_error_naming_argument_value_and_allowed_set(
    loop_gain_2, option, value, allowed
):
    with pytest.raises(ValueError) as err:
        _certify(loop_gain_2, **{option: value})
    assert f"{option}={value!r}" in str(err.value)
    assert allowed in str(err.value)


@pytest.mark.parametrize(("option", "value"), [("working_set", 0), ("p_params", [3])])
def test_bad_working_set_or_p_params_raises_value_error_naming_it(loop_gain_2, option, value):
    with pytest.raises(ValueError, match=re.escape(f"{option}={value!r}")):
        _certify(loop_gain_2, **{option: value})


def test_default_coordinates_are_k_scaled_and_plain_drops_the_k_scaling(loop_gain_2):
    scaled = _certify(loop_gain_2)
    plain = _certify(loop_gain_2, coordinates="plain")
    assert scaled.certified and plain.certified
    assert any(K_SCALED_NOTE in note for note in scaled.notes)
    assert not any(K_SCALED_NOTE in note for note in plain.notes)
    # the K-scaled functional adds the ratio K(t)/K(t - τ) as a rate coordinate: twice the vertices
    assert scaled.n_lmis == 2 * plain.n_lmis


def test_working_set_coupling_and_p_params_reach_the_analysis(loop_gain_2):
    res = _certify(loop_gain_2, working_set=1, coupling="per_point", p_params=[0])
    assert res.certified
    assert any(note.startswith("working set: LMI imposed at") for note in res.notes)
    assert res.n_lmis < _certify(loop_gain_2).n_lmis  # P in K only: fewer rate vertices


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
