"""The research entry (:mod:`research.synthesis_forms`): the Wirtinger analysis' formulation options
reach the analysis (real solves) and are validated; the shipped signatures carry none of them."""

from __future__ import annotations

import inspect
import re
from typing import Any

import numpy as np
import pytest

from pressor.synthesis.artifact import default_artifact_path, load_artifact
from pressor.synthesis.certificates.interface import AnalysisResult
from pressor.synthesis.families.smith.design import (
    certify_smith,
    design_smith,
    nominal_centre,
    smith_loops,
)
from pressor.synthesis.families.smith.law import SmithLPV
from pressor.synthesis.problem.reconstruct import scaling_of
from research.synthesis_forms import certify_smith_form

K_SCALED_NOTE = "K-scaled coordinates"


@pytest.fixture(scope="module")
def loop_gain_2() -> dict[str, Any]:
    """Loop gain 2 on the shipped model at K 0.25 and 1 (T 150 s, τ 40 s): the ends of the box on
    which the plain coordinates certify it too (docs/DESIGN-CHOICES.md, "The certified feedback")."""
    art = load_artifact(default_artifact_path())
    model = art.model_config
    law = SmithLPV(2.0, model.omega, model.lambda_)
    k_lo, k_hi = 0.25, 1.0
    points = np.array([[k_lo, 150.0, 40.0], [k_hi, 150.0, 40.0]])
    return {
        "systems": smith_loops(law, model, points),
        "points": points,
        "centre": nominal_centre(law, model),
        "model": model,
        "scaling": scaling_of(art),
    }


def _certify(case: dict[str, Any], **options: Any) -> AnalysisResult:
    return certify_smith_form(
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


ABLATIONS = {"rate_form", "working_set", "coupling", "p_params", "coordinates"}


@pytest.mark.parametrize("shipped_fn", [certify_smith, design_smith])
def test_the_shipped_smith_functions_take_no_formulation_option(shipped_fn):
    assert not ABLATIONS & set(inspect.signature(shipped_fn).parameters)


def test_verify_artifact_takes_no_formulation_option():
    from pressor.synthesis.verification.verify import verify_artifact

    assert "all_points_at_once" not in inspect.signature(verify_artifact).parameters


def test_the_default_form_is_the_shipped_certificate(loop_gain_2):
    shipped = certify_smith(
        loop_gain_2["systems"],
        loop_gain_2["points"],
        loop_gain_2["centre"],
        loop_gain_2["model"],
        loop_gain_2["scaling"],
        p_dependence="affine",
    )
    research = _certify(loop_gain_2)
    assert shipped.gamma == research.gamma and shipped.n_lmis == research.n_lmis


def test_every_registered_family_has_its_straightforward_cases():
    import research.synthesis_forms as research
    from pressor.synthesis.families.registry import family_named, structures

    kinds = {type(family_named(name)) for name in structures()}
    assert set(research._ALL_POINTS) == kinds and set(research._SYNTH_CASES) == kinds
