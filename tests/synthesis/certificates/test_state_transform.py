"""State transforms of the analysis LMI: whitening by a Lyapunov matrix, explicit transforms."""

from __future__ import annotations

import numpy as np
import pytest

from pressor.synthesis.certificates.state_transform import transform_of, whitening_transform
from pressor.synthesis.problem.closed_loop import DelaySystem


def test_whitening_maps_the_lyapunov_matrix_to_identity() -> None:
    p = np.array([[4.0, 1.0], [1.0, 1e-3 + 0.25]])
    t = whitening_transform(p)
    assert np.allclose(t.T @ p @ t, np.eye(2), atol=1e-9)
    with pytest.raises(ValueError, match="positive definite"):
        whitening_transform(-p)


def test_a_singular_explicit_transform_is_rejected() -> None:
    one = np.eye(2)
    system = DelaySystem(-one, 0 * one, one, one, 0 * one, 0 * one, 1.0)
    with pytest.raises(ValueError, match="invertible"):
        transform_of([system], 1.0, np.ones((2, 2)))
