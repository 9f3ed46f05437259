"""Exact sampled-data (ZOH) discretisation of the delayed controller, input filter and integrator.

The synthesis controller (``pressor.synthesis.problem.reconstruct.controller_at``, physical units, time in
s) is::

    dx_k/dt = Ak x_k + Adk x_k(t - tau) + Bk y,      y = [e_mmhg, x_e_mmhg_s]
    u_a     = Ck x_k + Cdk x_k(t - tau) + Dk y
    du/dt   = -Lambda u + Omega u_a                  (u: infusion command, ml/h)
    dx_e/dt = e                                      (x_e: mmHg*s)

At every tabulation node it is folded into one composite system with state
``z = [x_k (n_k), u, x_e]`` and input ``v = [x_d (n_k), e]`` where ``x_d = x_k(t - tau)``::

    dz/dt = Ac z + Bc v

and discretised exactly for inputs held over a sample (ZOH, period Ts). The result is stored in the
*increment* (delta-operator) realisation::

    z[k+1] = z[k] + M @ [z[k]; v[k]],     M = [Phi - I, Gamma] = Ts * [A_delta, B_delta]

Storing ``Phi - I`` instead of the near-identity ``Phi = exp(Ac Ts)`` keeps the small per-sample
increments representable in fixed point: at Ts = 0.1 s the diagonal of Phi is 1 - O(1e-2..1e-5),
which a Q15 (or even Q31) coefficient would round to 1 and lose the slow dynamics entirely.

Every node uses the same state coordinates (the artifact's reconstruction shares them across the
box; this module never transforms a node on its own), so the tables can be interpolated entrywise.

Deviations from the continuous controller (the documented discretisation error):

* ``e`` is sampled and held (ZOH) — exact for the sampled loop the runtime actually runs;
* ``x_d`` is held over the sample at its value at t_k - tau (read from a ring buffer of past x_k,
  linearly interpolated for fractional delays); the continuous controller sees it vary within the
  sample, an O(Ts * |dx_k/dt|) difference;
* the x_e row is exact (a ramp under ZOH ``e``).

How ``M`` is computed, and why not with ``scipy.linalg.expm``: the generated module's float tables
must be the same bytes on every CPU (docs/PLATFORM-NOTES.md, "The generated module on any CPU").
``expm`` and ``@`` go through OpenBLAS, whose kernel (and so its summation order and use of FMA)
depends on the CPU's vector width: on an AVX2-only CPU 1075 of the default module's 21,312 float
coefficients came out up to 4 ulp away from the AVX-512 ones. Here every operation after building
``Ac`` and ``Bc`` (elementwise IEEE products, the same bits everywhere) is done in Python's
``decimal`` arithmetic with :data:`WORKING_DIGITS` significant digits. ``decimal`` (libmpdec) is
software integer arithmetic in which each operation is correctly rounded to the context's
precision; no BLAS, SIMD or FMA is involved, so the digits are fixed by the inputs alone. Each
entry of ``M`` is then rounded to double once. The working error (about 1e-38 relative to the
entries' scale) is 22 orders of magnitude below half an ulp, so the double is the correctly rounded
value of the exact ``M`` of the double ``Ac``, ``Bc`` and ``Ts`` (unless that value lies within
1e-38 of a rounding midpoint), whatever the algorithm's details: a test checks that 40 and 80
digits give the same doubles.

The series, with ``Y = Ac h`` and ``h = Ts / 2^s`` (``s`` the least integer with
``||Y||_inf <= 1/2``)::

    phi1(Y) = sum_k Y^k / (k + 1)!       (Horner form, truncated where the next term < 1e-42)
    exp(Y) - I = Y phi1(Y),              Psi_h = int_0^h exp(Ac t) dt = h phi1(Y)

and ``s`` doublings ``E1 <- E1 F``, ``Psi <- F Psi`` with ``F = E1 + 2I`` (from
``exp(2Y) - I = (exp(Y) - I)(exp(Y) + I)`` and ``Psi_2h = (I + exp(Y)) Psi_h``), so that
``Phi - I = E1`` is summed directly, never formed as a difference. ``Gamma = Psi Bc``.

Measured on the default design (202 seeded nodes of its box, against 80 digits): ``expm`` was
off by up to 4 ulp per entry, this method by 0 (correctly rounded), and a float version of the same
series with ``math.fsum`` dot products (CPU-independent too) by up to 2 ulp. Cost per node on the
2-core development machine: 0.3-1 ms here, 0.2 ms for the ``fsum`` version, 0.03 ms for ``expm`` on
one OpenBLAS thread but 2-17 ms on OpenBLAS's default threads, which ``pressor codegen`` used; so
``pressor codegen`` got faster, and the decimal version was chosen over the ``fsum`` one (about 2 s
more for the ~5200 nodes a design discretises) because its bits are the exact answer's, not one
algorithm's: any correct implementation reproduces them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from decimal import Context, Decimal, InvalidOperation, Overflow, localcontext
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "WORKING_DIGITS",
    "ContinuousController",
    "DelayedControllerMatrices",
    "composite_continuous",
    "discretise_node",
    "zoh_increment",
]

Matrix = NDArray[np.float64]

#: Significant decimal digits of every intermediate of :func:`zoh_increment`. 40 leaves 23 digits
#: between the working error and half an ulp of a double (17 digits); 80 gives the same doubles.
WORKING_DIGITS = 40

# A row of a matrix as its non-zero entries (column, value): the composite matrices are about half
# zeros, and skipping them halves the decimal work without changing any digit (x + 0 * y == x).
_SparseRows = list[list[tuple[int, Decimal]]]


class ContinuousController(Protocol):
    """Anything with the ``pressor.synthesis.problem.reconstruct.DelayedController`` matrices.

    Time in s.
    """

    Ak: Matrix
    Adk: Matrix
    Bk: Matrix
    Ck: Matrix
    Cdk: Matrix
    Dk: Matrix


@dataclass(frozen=True)
class DelayedControllerMatrices:
    """A plain delayed controller (the same fields as ``DelayedController``), e.g. for tests."""

    Ak: Matrix
    Adk: Matrix
    Bk: Matrix
    Ck: Matrix
    Cdk: Matrix
    Dk: Matrix


def composite_continuous(
    controller: ContinuousController, omega: float, lambda_: float
) -> tuple[Matrix, Matrix]:
    """Continuous composite ``(Ac, Bc)`` for state ``[x_k, u, x_e]`` and input ``[x_d, e]``.

    Parameters
    ----------
    controller
        Delayed controller matrices (time in s); ``Bk`` is n_k x 2, ``Ck``/``Cdk`` 1 x n_k,
        ``Dk`` 1 x 2, the y channels being [e (mmHg), x_e (mmHg*s)].
    omega, lambda_
        Input filter u = omega/(s + lambda_) u_a, in 1/s.

    Returns
    -------
    Ac, Bc
        ``(n_k+2) x (n_k+2)`` and ``(n_k+2) x (n_k+1)`` matrices in 1/s.
    """
    Ak = np.atleast_2d(np.asarray(controller.Ak, float))
    Adk = np.atleast_2d(np.asarray(controller.Adk, float))
    Bk = np.atleast_2d(np.asarray(controller.Bk, float))
    Ck = np.asarray(controller.Ck, float).reshape(1, -1)
    Cdk = np.asarray(controller.Cdk, float).reshape(1, -1)
    Dk = np.asarray(controller.Dk, float).reshape(1, 2)
    n = Ak.shape[0]
    if Adk.shape != (n, n) or Bk.shape != (n, 2) or Ck.shape[1] != n or Cdk.shape[1] != n:
        raise ValueError(
            f"controller shapes Ak{Ak.shape} Adk{Adk.shape} Bk{Bk.shape} Ck{Ck.shape} "
            f"Cdk{Cdk.shape}: expected n x n, n x n, n x 2, 1 x n, 1 x n"
        )
    nz = n + 2
    Ac = np.zeros((nz, nz))
    Bc = np.zeros((nz, n + 1))
    Ac[:n, :n] = Ak
    Ac[:n, n + 1] = Bk[:, 1]
    Ac[n, :n] = omega * Ck[0]
    Ac[n, n] = -lambda_
    Ac[n, n + 1] = omega * Dk[0, 1]
    Bc[:n, :n] = Adk
    Bc[:n, n] = Bk[:, 0]
    Bc[n, :n] = omega * Cdk[0]
    Bc[n, n] = omega * Dk[0, 0]
    Bc[n + 1, n] = 1.0
    return Ac, Bc


def _sparse(rows: list[list[Decimal]]) -> _SparseRows:
    return [[(j, v) for j, v in enumerate(row) if v] for row in rows]


def _matmul(a: _SparseRows, b: list[list[Decimal]], n_col: int) -> list[list[Decimal]]:
    """``a @ b`` in the current decimal context; the sum runs over columns of ``a`` in order."""
    out = []
    for row in a:
        if not row:
            out.append([Decimal(0)] * n_col)
            continue
        j0, a0 = row[0]
        acc = [a0 * y for y in b[j0]]
        for j, a_ij in row[1:]:
            acc = [x + a_ij * y for x, y in zip(acc, b[j])]  # noqa: B905 (rows of length n_col)
        out.append(acc)
    return out


def _to_double(x: Decimal) -> float:
    """The double nearest ``x`` (CPython converts through its correctly rounded ``float(str)``);
    a signed zero becomes +0.0 (the sign of an exact zero is an accident of the summation order,
    and ``-0.0`` would be written into the generated source)."""
    return float(x) if x else 0.0


def zoh_increment(
    Ac: Matrix, Bc: Matrix, sample_period_s: float, digits: int = WORKING_DIGITS
) -> Matrix:
    """``[exp(Ac Ts) - I, (int_0^Ts exp(Ac t) dt) Bc]``, each entry the double nearest its exact value.

    Computed in ``digits``-digit decimal arithmetic and rounded to double once (module docstring:
    the result does not depend on the CPU, BLAS or vector width).

    Parameters
    ----------
    Ac, Bc
        ``n x n`` and ``n x m`` continuous matrices (1/s), finite.
    sample_period_s
        Ts (s), positive and finite.
    digits
        Working precision in significant decimal digits.

    Returns
    -------
    ndarray
        ``n x (n + m)``, dimensionless (``Phi - I``) and ``Bc``'s units times s (``Gamma``).

    Raises
    ------
    ValueError
        Non-finite ``Ac`` or ``Bc``, or a non-positive or non-finite ``sample_period_s``.
    """
    ts = float(sample_period_s)
    if not (ts > 0.0 and math.isfinite(ts)):
        raise ValueError(f"sample_period_s={sample_period_s!r} must be a positive finite time (s)")
    a_rows = np.asarray(Ac, dtype=np.float64).tolist()
    b_rows = np.asarray(Bc, dtype=np.float64).tolist()
    n = len(a_rows)
    n_in = len(b_rows[0]) if b_rows else 0
    if any(len(r) != n for r in a_rows) or len(b_rows) != n:
        raise ValueError(f"Ac {np.shape(Ac)} and Bc {np.shape(Bc)}: expected n x n and n x m")
    if not all(math.isfinite(v) for r in a_rows + b_rows for v in r):
        raise ValueError("Ac and Bc must be finite")
    # Scaling and the number of terms are chosen from float norms (math.fsum: correctly rounded,
    # the same on every CPU); they decide only how the exact value is approached, not its digits.
    norm = ts * max((math.fsum(abs(v) for v in r) for r in a_rows), default=0.0)
    s = 0
    while norm > 0.5 * 2.0**s:
        s += 1
    y_norm = norm / 2.0**s
    tail_tol = 10.0 ** -(digits + 2)
    # left_out bounds the norm of the first term left out, ||Y||^(terms+1) / (terms+2)!; with
    # ||Y|| <= 1/2 the whole tail is under twice that, and phi1(Y) has norm near 1, so stopping
    # below 10^-(digits+2) keeps the truncation two digits below the working precision.
    terms, left_out = 1, y_norm * y_norm / 6.0
    while left_out >= tail_tol:
        terms += 1
        left_out *= y_norm / (terms + 2)
    ctx = Context(prec=digits, traps=[InvalidOperation, Overflow])
    with localcontext(ctx):
        h = Decimal(ts) / (2**s)
        y = _sparse([[Decimal(v) * h for v in r] for r in a_rows])
        one, two = Decimal(1), Decimal(2)
        # Horner: phi <- I + Y phi / (k + 1), k = terms .. 1, gives sum_{k<=terms} Y^k / (k+1)!
        phi = [[one if i == j else Decimal(0) for j in range(n)] for i in range(n)]
        for k in range(terms, 0, -1):
            c = Decimal(k + 1)
            phi = [[v / c for v in row] for row in _matmul(y, phi, n)]
            for i in range(n):
                phi[i][i] += one
        e1 = _matmul(y, phi, n)  # exp(Y) - I
        psi = [[v * h for v in row] for row in phi]
        for _ in range(s):
            f = [row[:] for row in e1]
            for i in range(n):
                f[i][i] += two
            f_rows = _sparse(f)
            e1 = _matmul(f_rows, e1, n)  # F commutes with E1 and Psi (all functions of Ac)
            psi = _matmul(f_rows, psi, n)
        gamma = _matmul(_sparse(psi), [[Decimal(v) for v in r] for r in b_rows], n_in)
        out = [[_to_double(v) for v in e1[i] + gamma[i]] for i in range(n)]
    return np.array(out, dtype=np.float64).reshape(n, n + n_in)


def discretise_node(
    controller: ContinuousController, omega: float, lambda_: float, sample_period_s: float
) -> Matrix:
    """Increment matrix ``M = [Phi - I, Gamma]`` of one node (ZOH, period ``sample_period_s``).

    ``Phi - I = exp(Ac Ts) - I`` is summed as the series ``Y phi1(Y)`` (no cancellation from
    subtracting I from a near-identity matrix) and ``Gamma = (int_0^Ts exp(Ac t) dt) Bc``, both in
    decimal arithmetic and rounded once (:func:`zoh_increment`; the module docstring says why).

    Parameters
    ----------
    controller
        Delayed controller matrices (time in s), see :func:`composite_continuous`.
    omega, lambda_
        Input filter (1/s).
    sample_period_s
        Ts (s).

    Returns
    -------
    ndarray
        ``(n_k+2) x (2 n_k + 3)``: columns ``[z (n_k+2), x_d (n_k), e]``. The x_e row is
        ``[0, ..., 0, Ts]`` exactly.
    """
    if not (sample_period_s > 0.0 and np.isfinite(sample_period_s)):
        raise ValueError(f"sample_period_s={sample_period_s!r} must be a positive finite time (s)")
    Ac, Bc = composite_continuous(controller, omega, lambda_)
    nz = Ac.shape[0]
    m = zoh_increment(Ac, Bc, sample_period_s)
    # The integrator row is structurally [0, ..., 0, Ts]: the series gives those values to 40
    # digits already; setting them states the structure rather than relying on it.
    m[nz - 1, :] = 0.0
    m[nz - 1, -1] = sample_period_s
    return m
