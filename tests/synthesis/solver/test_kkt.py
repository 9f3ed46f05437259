"""KKT backends: every backend certifies, a numerical failure falls back to the next, chains parse.

Real Clarabel solves throughout: a tiny frozen delay loop in the default suite, the shipped design
per backend in the slow tests (``pytest -m slow``).
"""

from __future__ import annotations

import numpy as np
import pytest

from pressor.synthesis.artifact import default_artifact_path, load_artifact
from pressor.synthesis.certificates.wirtinger.analysis import analyse_wirtinger
from pressor.synthesis.families.smith.design import design_smith, recheck_smith_artifact
from pressor.synthesis.problem.closed_loop import DelaySystem
from pressor.synthesis.problem.config_toml import load_config
from pressor.synthesis.solver.kkt import (
    DEFAULT_KKT_CHAIN,
    KKT_METHODS,
    KktAttempt,
    current_kkt_chain,
    kkt_chain,
    parse_kkt_chain,
)

#: a setting that stops every interior-point step short: Clarabel ends "InsufficientProgress"
STALL = {"max_step_fraction": 1e-9}


def _scalar_loop() -> DelaySystem:
    """dx/dt = -x - 0.5 x(t - 2) + w, z = x: stable for every delay."""
    one = np.ones((1, 1))
    return DelaySystem(-1.0 * one, -0.5 * one, one, one, 0 * one, 0 * one, 2.0)


def _analyse(progress=None):
    zero = np.zeros(1)
    return analyse_wirtinger(
        [_scalar_loop()], np.zeros((1, 1)), zero, zero, 2.0, "constant", progress=progress
    )


def _hinf_norm() -> float:
    """The loop's exact H-inf norm, max over w of 1 / |1 + jw + 0.5 e^(-2jw)| (a sweep)."""
    w = np.linspace(0.0, 20.0, 200_001)
    return float(1.0 / np.abs(1.0 + 1j * w + 0.5 * np.exp(-2j * w)).min())  # 1.0403


@pytest.mark.parametrize("method", KKT_METHODS)
def test_each_backend_alone_certifies_a_delay_loop_near_its_exact_gain(method):
    with kkt_chain([method]):
        res = _analyse()
    assert res.certified and res.gamma is not None
    assert _hinf_norm() <= res.gamma < 1.01 * _hinf_norm()
    assert not any("KKT fallback" in note for note in res.notes)


def test_a_numerical_failure_of_the_first_backend_is_solved_by_the_next_and_reported():
    lines: list[str] = []
    with kkt_chain([KktAttempt("faer", STALL), "qdldl"]):
        res = _analyse(progress=lines.append)
    assert res.certified and res.gamma is not None and res.gamma < 1.01 * _hinf_norm()
    stalled = "faer(max_step_fraction=1e-09): InsufficientProgress"
    assert f"KKT fallback: {stalled}, then qdldl" in res.notes
    assert any(
        "InsufficientProgress" in line and "solving again with qdldl" in line for line in lines
    )


def test_a_forced_single_backend_that_fails_ends_in_a_solver_error_not_a_certificate():
    with kkt_chain([KktAttempt("faer", STALL)]):
        res = _analyse()
    assert not res.certified and res.status == "solver_error"
    assert "Clarabel ended InsufficientProgress" in res.notes


def test_the_chain_is_restored_after_the_block_and_defaults_to_faer_then_qdldl():
    assert [a.method for a in DEFAULT_KKT_CHAIN] == ["faer", "qdldl"]
    with kkt_chain(["qdldl"]):
        assert current_kkt_chain() == (KktAttempt("qdldl"),)
    assert current_kkt_chain() == DEFAULT_KKT_CHAIN


@pytest.mark.parametrize("text", ["", "faer,faer", "mkl", "faer,,qdldl"])
def test_a_bad_chain_text_is_refused_naming_it_and_the_allowed_names(text):
    with pytest.raises(ValueError) as err:
        parse_kkt_chain(text)
    assert repr(text) in str(err.value) and "'faer', 'qdldl'" in str(err.value)


def test_chain_text_parses_in_order():
    assert parse_kkt_chain("qdldl, faer") == (KktAttempt("qdldl"), KktAttempt("faer"))


@pytest.mark.slow
@pytest.mark.parametrize("method", KKT_METHODS)
def test_the_shipped_design_certifies_with_each_backend(method):
    with kkt_chain([method]):
        art = design_smith(load_config())
    certified, margins = recheck_smith_artifact(art)
    assert certified and np.all(margins > 0)
    # every backend reaches the shipped certificate's gamma (19.32) to within 1 %
    assert art.gamma == pytest.approx(load_artifact(default_artifact_path()).gamma, rel=0.01)
