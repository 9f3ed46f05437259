"""The ZOH increment matrix (pressor.codegen.discretise): accurate, correctly rounded, and the same bits
whatever BLAS kernel the process runs."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from decimal import Decimal, localcontext
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

from pressor.codegen import pipeline as pl
from pressor.codegen.discretise import composite_continuous, discretise_node, zoh_increment
from tests.support.codegen_helpers import BOX, TS, example_controller
from tests.support.generated_currency import node_matrices_digest

#: Points of the hand-built controller's box (K, T, tau): corners, centre, an off-centre point.
POINTS = [tuple(BOX[:, 0]), tuple(BOX[:, 1]), tuple(BOX.mean(axis=1)), (0.3, 180.0, 12.5)]


def _composites(gain: float = 1.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """(Ac, Bc) of the hand-built controller at POINTS, Ac times ``gain`` (1/s)."""
    out = []
    for rho in POINTS:
        Ac, Bc = composite_continuous(example_controller(rho), 0.1, 0.1)
        out.append((Ac * gain, Bc))
    return out


def _scipy_increment(Ac: np.ndarray, Bc: np.ndarray, ts: float) -> np.ndarray:
    """The previous method: expm of the augmented matrix [[Ac, I], [0, 0]] Ts through OpenBLAS."""
    n = Ac.shape[0]
    big = np.zeros((2 * n, 2 * n))
    big[:n, :n] = Ac
    big[:n, n:] = np.eye(n)
    psi = expm(big * ts)[:n, n:]
    return np.hstack([Ac @ psi, psi @ Bc])


# gain 1: ||Ac Ts|| < 1/2, no doubling; gain 300: ||Ac Ts|| ~ 13, five doublings.
@pytest.mark.parametrize("gain", [1.0, 300.0])
def test_increment_agrees_with_scipy_expm_to_a_few_units_in_the_last_place(gain: float) -> None:
    for Ac, Bc in _composites(gain):
        got = zoh_increment(Ac, Bc, TS)
        ref = _scipy_increment(Ac, Bc, TS)
        row_scale = np.max(np.abs(ref), axis=1, keepdims=True)
        assert np.max(np.abs(got - ref) / row_scale) < 1e-14


@pytest.mark.parametrize("gain", [1.0, 300.0])
def test_increment_is_the_same_doubles_at_40_and_80_working_digits(gain: float) -> None:
    """40 digits are enough for every entry to be the correctly rounded exact value."""
    for Ac, Bc in _composites(gain):
        assert np.array_equal(zoh_increment(Ac, Bc, TS), zoh_increment(Ac, Bc, TS, digits=80))


@pytest.mark.parametrize("rate", [1e-9, 1e-3, 0.7, 30.0])
def test_scalar_increment_is_the_correctly_rounded_expm1_and_its_integral(rate: float) -> None:
    """dx/dt = -a x + b: Phi - I = expm1(-a Ts) and Gamma = -expm1(-a Ts)/a, each the double nearest
    the exact value (decimal's exp is correctly rounded), with no cancellation for a slow mode."""
    got = zoh_increment(np.array([[-rate]]), np.array([[1.0]]), TS)
    with localcontext() as ctx:
        ctx.prec = 60
        em1 = (-Decimal(rate) * Decimal(TS)).exp() - 1
        want = [float(em1), float(-em1 / Decimal(rate))]
    assert got.tolist() == [want]
    assert math.isclose(got[0, 0], math.expm1(-rate * TS), rel_tol=4e-16)


def _structural_nonzeros(Ac: np.ndarray, Bc: np.ndarray) -> np.ndarray:
    """Where [exp(Ac Ts) - I, Psi Bc] can be non-zero: (i, j) of Phi - I iff a path of Ac's
    non-zeros leads from i to j; Psi adds the identity."""
    n = Ac.shape[0]
    step = (Ac != 0).astype(int)
    reach = step.copy()
    for _ in range(n):
        reach = ((reach + reach @ step) > 0).astype(int)
    psi = ((reach + np.eye(n, dtype=int)) > 0).astype(int)
    return np.hstack([reach > 0, (psi @ (Bc != 0).astype(int)) > 0])


def test_increment_is_exactly_zero_and_never_negative_zero_where_the_structure_is_zero() -> None:
    for Ac, Bc in _composites():
        got = zoh_increment(Ac, Bc, TS)
        assert np.array_equal(got != 0.0, _structural_nonzeros(Ac, Bc))
        assert not np.any(np.signbit(got[got == 0.0]))


def test_integrator_row_is_exactly_zero_then_the_sample_period() -> None:
    m = discretise_node(example_controller(POINTS[2]), 0.1, 0.1, TS)
    assert m[-1].tolist() == [0.0] * (m.shape[1] - 1) + [TS]


@pytest.mark.parametrize(
    "Ac, Bc, ts",
    [
        (np.array([[np.nan]]), np.array([[1.0]]), TS),
        (np.array([[-1.0]]), np.array([[np.inf]]), TS),
        (np.array([[-1.0]]), np.array([[1.0]]), 0.0),
        (np.array([[-1.0]]), np.array([[1.0]]), math.inf),
        (np.eye(2), np.ones((3, 1)), TS),
    ],
)
def test_increment_rejects_non_finite_or_misshapen_input_naming_it(Ac, Bc, ts) -> None:
    with pytest.raises(ValueError, match="finite|expected"):
        zoh_increment(Ac, Bc, ts)


@pytest.mark.skipif(not pl.DEFAULT_ARTIFACT.is_file(), reason="no shipped design")
def test_increment_bits_do_not_depend_on_the_openblas_kernel() -> None:
    """OPENBLAS_CORETYPE=Haswell (the AVX2 kernels an AVX-512 CPU would not pick) moved 1075 of
    the default module's float coefficients by up to 4 ulp with scipy's expm; a child process on
    those kernels must now compute the same bits as this one."""
    flags = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").is_file() else ""
    if not {"avx2", "fma"} <= set(flags.split()):
        pytest.skip("needs an x86-64 CPU with AVX2 and FMA to run OpenBLAS's Haswell kernels")
    code = (
        "from pathlib import Path; from tests.support.generated_currency import "
        f"node_matrices_digest as d; print(d(Path({str(pl.DEFAULT_ARTIFACT)!r})))"
    )
    env = {**os.environ, "OPENBLAS_CORETYPE": "Haswell"}
    child = subprocess.run(
        [sys.executable, "-c", code],
        cwd=pl.REPO_ROOT,
        env=env,
        capture_output=True,
        text=True,
        check=True,
        timeout=300,
    )
    assert child.stdout.strip() == node_matrices_digest(pl.DEFAULT_ARTIFACT)
