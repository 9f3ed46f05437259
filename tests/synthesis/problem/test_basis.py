"""The parameter basis: its terms, their order and their derivatives, for every p-dependence."""

from __future__ import annotations

import numpy as np
import pytest

from pressor.synthesis.problem.basis import (
    basis_derivatives,
    basis_terms,
    basis_weights,
    evaluate,
    term_parameters,
)


def test_full_basis_at_a_point_is_the_papers_seven_terms() -> None:
    w = basis_weights(np.array([[0.5, -2.0, 0.25]]))
    np.testing.assert_array_equal(w, [[1.0, 0.5, -2.0, 0.25, 0.125, 2.0, 0.03125]])
    d = basis_derivatives(np.array([[0.5, -2.0, 0.25]]))
    expected = np.zeros((1, 3, 7))
    expected[0, 0, [1, 4]] = [1.0, 0.5]
    expected[0, 1, [2, 5]] = [1.0, -2.0]
    expected[0, 2, [3, 6]] = [1.0, 0.25]
    np.testing.assert_array_equal(d, expected)


@pytest.mark.parametrize(
    ("p_dependence", "weights", "derivatives"),
    [
        ("constant", [1.0], [[0.0, 0.0, 0.0]]),
        ("affine", [1.0, 0.25], [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
        (
            "quadratic",
            [1.0, 0.25, 0.03125],
            [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.25]],
        ),
    ],
)
def test_subset_basis_keeps_the_terms_of_the_chosen_parameters_up_to_the_degree(
    p_dependence: str, weights: list[float], derivatives: list[list[float]]
) -> None:
    w, d = basis_terms(np.array([[0.5, -2.0, 0.25]]), p_dependence, params=[2])
    np.testing.assert_array_equal(w, [weights])
    np.testing.assert_array_equal(d, [derivatives])
    assert term_parameters(p_dependence, [2]) == (None, 2, 2)[: len(weights)]


def test_two_parameters_are_ordered_by_degree_then_parameter() -> None:
    w, d = basis_terms(np.array([[3.0, -1.0], [0.0, 2.0]]), "quadratic", params=[1, 0])
    np.testing.assert_array_equal(w, [[1.0, -1.0, 3.0, 0.5, 4.5], [1.0, 2.0, 0.0, 2.0, 0.0]])
    np.testing.assert_array_equal(
        d[0], [[0.0, 0.0], [0.0, 1.0], [1.0, 0.0], [0.0, -1.0], [3.0, 0.0]]
    )
    assert term_parameters("quadratic", [1, 0]) == (None, 1, 0, 1, 0)


def test_evaluate_sums_the_weighted_coefficients() -> None:
    coeffs = np.arange(7.0).reshape(7, 1, 1)  # M0 = 0, M11 = 1, ..., M32 = 6
    # 1*0 + 0.5*1 - 2*2 + 0.25*3 + 0.125*4 + 2*5 + 0.03125*6
    value = evaluate(coeffs, np.array([[0.5, -2.0, 0.25]]))
    assert value.shape == (1, 1, 1)
    assert value[0, 0, 0] == pytest.approx(7.9375)


def test_unknown_p_dependence_is_rejected() -> None:
    with pytest.raises(ValueError):
        basis_terms(np.zeros((1, 3)), "cubic")
