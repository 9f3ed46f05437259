"""Tabulation grid for run-time interpolation, chosen and proven stable.

Multilinear interpolation of controller matrices tabulated at a coarse grid can destabilise loops
that the exactly reconstructed controller keeps stable (issue 4 measured 82 of 158 frozen loops
unstable for one 3x3x3 design). So the tabulation grid is a *uniform* grid over the design box,
independent of the synthesis grid (the artifact reconstructs the controller at any rho), refined
until every check passes:

1. the sampled frozen closed loop (FOPDT patient K/(T s + 1) e^(-tau s) under ZOH, the discrete
   controller with its delayed state read from a shift buffer, exactly what the generated step
   does) is stable at every cell midpoint and at seeded random interior points;
2. at the same points the interpolated increment matrix is within ``rel_tol`` (row-wise relative
   Frobenius error) of the matrix discretised from the exactly reconstructed controller.

A refinement doubles the spacing count of the axis whose edge midpoints show the largest error.

Frozen-loop check (:func:`unstable_root_count`). With ``s_k = [dMAP_k, z_k]`` the sampled loop is
``s_{k+1} = sum_j A_j s_{k-j}`` for lags ``j in {0, N-1, N, N+1}`` (tau = (N + f) Ts). Its
characteristic roots are the reciprocals of the zeros of ``g(w) = det(I - sum_j A_j w^(j+1))``;
the loop is stable iff g has no zero in the closed unit disc, i.e. iff the winding number of
g(e^(i theta)) about 0 is zero (argument principle; g(0) = 1). Sampling is refined until no phase
step exceeds pi/4, so a root on or near the circle cannot be stepped over unnoticed.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from codegen.discretise import ContinuousController, discretise_node

__all__ = [
    "GridCheck",
    "TabulationGrid",
    "TabulationProof",
    "build_tables",
    "check_grid",
    "choose_grid",
    "frozen_loop_matrices",
    "interpolate",
    "unstable_root_count",
]

Matrix = NDArray[np.float64]
ControllerFn = Callable[[NDArray[np.float64]], ContinuousController]


@dataclass(frozen=True)
class TabulationGrid:
    """A uniform grid over the box; axis i has ``counts[i]`` nodes from ``lo[i]`` to ``hi[i]``.

    Units per axis: K [mmHg/(ml/h)], T [s], tau [s].
    """

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    counts: tuple[int, int, int]

    def __post_init__(self) -> None:
        for i in range(3):
            if not self.hi[i] > self.lo[i]:
                raise ValueError(f"grid axis {i}: hi={self.hi[i]} must exceed lo={self.lo[i]}")
            if self.counts[i] < 2:
                raise ValueError(f"grid axis {i}: counts={self.counts[i]} must be >= 2")

    @property
    def spacing(self) -> tuple[float, float, float]:
        """Node spacing per axis (physical units)."""
        return tuple((self.hi[i] - self.lo[i]) / (self.counts[i] - 1) for i in range(3))  # type: ignore[return-value]

    @property
    def inv_spacing(self) -> tuple[float, float, float]:
        """Reciprocal spacing per axis (stored so the step never divides)."""
        return tuple((self.counts[i] - 1) / (self.hi[i] - self.lo[i]) for i in range(3))  # type: ignore[return-value]

    def axes(self) -> tuple[Matrix, Matrix, Matrix]:
        """The node coordinates per axis."""
        return tuple(np.linspace(self.lo[i], self.hi[i], self.counts[i]) for i in range(3))  # type: ignore[return-value]

    def nodes(self) -> Matrix:
        """All nodes, shape (nK*nT*ntau, 3), K slowest, tau fastest (C order)."""
        a, b, c = self.axes()
        return np.stack(np.meshgrid(a, b, c, indexing="ij"), axis=-1).reshape(-1, 3)

    def cell_midpoints(self) -> Matrix:
        """Centres of all cells, shape (prod(counts-1), 3)."""
        mids = [0.5 * (ax[1:] + ax[:-1]) for ax in self.axes()]
        return np.stack(np.meshgrid(*mids, indexing="ij"), axis=-1).reshape(-1, 3)

    def refined(self, axis: int) -> TabulationGrid:
        """The grid with axis ``axis`` halved in spacing (old nodes kept)."""
        counts = list(self.counts)
        counts[axis] = 2 * counts[axis] - 1
        return TabulationGrid(self.lo, self.hi, tuple(counts))  # type: ignore[arg-type]


def build_tables(
    controller_fn: ControllerFn,
    grid: TabulationGrid,
    omega: float,
    lambda_: float,
    sample_period_s: float,
) -> Matrix:
    """Increment matrices at every node, shape ``(nK, nT, ntau, n_z, n_col)``."""
    mats = [
        discretise_node(controller_fn(rho), omega, lambda_, sample_period_s) for rho in grid.nodes()
    ]
    return np.asarray(mats).reshape(*grid.counts, *mats[0].shape)


def interpolate(tables: Matrix, grid: TabulationGrid, rho: Sequence[float]) -> Matrix:
    """Multilinear interpolation of ``tables`` at ``rho`` (clamped to the box, never extrapolated)."""
    idx = []
    frac = []
    inv = grid.inv_spacing
    for i in range(3):
        s = (min(max(float(rho[i]), grid.lo[i]), grid.hi[i]) - grid.lo[i]) * inv[i]
        j = min(int(s), grid.counts[i] - 2)
        idx.append(j)
        frac.append(s - j)
    out = np.zeros(tables.shape[3:])
    for ca in (0, 1):
        wa = frac[0] if ca else 1.0 - frac[0]
        for cb in (0, 1):
            wb = frac[1] if cb else 1.0 - frac[1]
            for cc in (0, 1):
                wc = frac[2] if cc else 1.0 - frac[2]
                out += wa * wb * wc * tables[idx[0] + ca, idx[1] + cb, idx[2] + cc]
    return out


def frozen_loop_matrices(
    m: Matrix, rho: Sequence[float], sample_period_s: float
) -> dict[int, Matrix]:
    """Lag matrices ``{j: A_j}`` of the sampled frozen loop ``s_{k+1} = sum_j A_j s_{k-j}``.

    Parameters
    ----------
    m
        Increment matrix ``[Phi - I, Gamma]`` of the controller (columns [z, x_d, e]).
    rho
        (K mmHg/(ml/h), T s, tau s); tau must be at least one sample period.
    sample_period_s
        Ts (s).

    Notes
    -----
    Step k of the generated controller uses e_k = -dMAP_k (target and baseline cancel in the
    linearised loop), reads x_d from the buffer at D = tau/Ts samples back (linear interpolation)
    and returns c_k = u_{k+1}. The patient sees c(t - tau) with c held over each sample.
    """
    K, T, tau = (float(r) for r in rho)
    ts = sample_period_s
    nz = m.shape[0]
    nk = nz - 2
    d = tau / ts
    if d < 1.0:
        raise ValueError(f"tau={tau} s shorter than one sample period {ts} s")
    n_lag = int(math.floor(d))
    f = d - n_lag
    ns = nz + 1
    mz, md, me = m[:, :nz], m[:, nz : nz + nk], m[:, nz + nk]
    a = math.exp(-ts / T)
    b0 = K * (1.0 - math.exp(-(1.0 - f) * ts / T))  # weight of c_{k-N}
    b1 = K * math.exp(-(1.0 - f) * ts / T) * (1.0 - math.exp(-f * ts / T))  # c_{k-N-1}
    iu = 1 + nk  # index of u inside s
    lags: dict[int, Matrix] = {}

    def lag(j: int) -> Matrix:
        if j not in lags:
            lags[j] = np.zeros((ns, ns))
        return lags[j]

    a0 = lag(0)
    a0[0, 0] = a
    a0[1:, 0] = -me
    a0[1:, 1:] = np.eye(nz) + mz
    # c_{k-N} = u(z_{k-N+1}): lag N-1; c_{k-N-1} = u(z_{k-N}): lag N.
    lag(n_lag - 1)[0, iu] += b0
    lag(n_lag)[0, iu] += b1
    lag(n_lag)[1:, 1 : 1 + nk] += (1.0 - f) * md
    if f > 0.0:
        lag(n_lag + 1)[1:, 1 : 1 + nk] += f * md
    return lags


def unstable_root_count(lags: dict[int, Matrix], radius: float = 1.0) -> int:
    """Number of characteristic roots with modulus >= ``radius`` (0 means stable).

    Counts the zeros of ``g(w) = det(I - sum_j A_j w^(j+1))`` inside ``|w| < 1/radius`` by the
    argument principle on a sampling of the circle refined until every phase step is < pi/4.
    """
    ns = next(iter(lags.values())).shape[0]
    degree = ns * (max(lags) + 1)
    r = 1.0 / radius
    points = 1 << max(10, math.ceil(math.log2(4 * degree)))
    while True:
        w = r * np.exp(1j * np.linspace(0.0, 2.0 * math.pi, points, endpoint=False))
        mat = np.broadcast_to(np.eye(ns, dtype=complex), (points, ns, ns)).copy()
        for j, aj in lags.items():
            mat -= (w ** (j + 1))[:, None, None] * aj[None, :, :]
        g = np.linalg.det(mat)
        if np.any(g == 0):
            return 1
        phase = np.angle(g)
        steps = np.diff(np.concatenate([phase, phase[:1]]))
        steps = (steps + math.pi) % (2.0 * math.pi) - math.pi
        if np.max(np.abs(steps)) < math.pi / 4 or points >= 1 << 22:
            return int(round(float(np.sum(steps)) / (2.0 * math.pi)))
        points *= 4


def row_relative_error(approx: Matrix, exact: Matrix) -> float:
    """max over rows of ||approx_i - exact_i|| / ||exact_i|| (rows with zero norm: absolute)."""
    num = np.linalg.norm(approx - exact, axis=1)
    den = np.linalg.norm(exact, axis=1)
    return float(np.max(np.where(den > 0, num / np.where(den > 0, den, 1.0), num)))


@dataclass(frozen=True)
class GridCheck:
    """Result of checking one tabulation grid.

    Attributes
    ----------
    points
        Checked rho points (n, 3), physical units.
    unstable
        Unstable characteristic-root counts of the interpolated frozen loop at each point.
    exact_unstable
        The same for the exactly reconstructed controller (a failure there is the design's, not
        the interpolation's).
    rel_error
        Row-wise relative error of the interpolated increment matrix at each point.
    """

    points: Matrix
    unstable: NDArray[np.int64]
    exact_unstable: NDArray[np.int64]
    rel_error: Matrix

    @property
    def passed_stability(self) -> bool:
        """Every interpolated frozen loop is stable where the exact one is."""
        return bool(np.all((self.unstable == 0) | (self.exact_unstable > 0)))

    def passed(self, rel_tol: float) -> bool:
        """Stability passed and every error within ``rel_tol``."""
        return self.passed_stability and float(np.max(self.rel_error)) <= rel_tol


def check_grid(
    controller_fn: ControllerFn,
    grid: TabulationGrid,
    tables: Matrix,
    points: Matrix,
    omega: float,
    lambda_: float,
    sample_period_s: float,
) -> GridCheck:
    """Frozen-loop stability and interpolation error of ``tables`` at ``points``."""
    unstable, exact_unstable, errors = [], [], []
    for rho in points:
        approx = interpolate(tables, grid, rho)
        exact = discretise_node(controller_fn(rho), omega, lambda_, sample_period_s)
        unstable.append(unstable_root_count(frozen_loop_matrices(approx, rho, sample_period_s)))
        exact_unstable.append(
            unstable_root_count(frozen_loop_matrices(exact, rho, sample_period_s))
            if unstable[-1]
            else 0
        )
        errors.append(row_relative_error(approx, exact))
    return GridCheck(
        points=np.asarray(points, float),
        unstable=np.asarray(unstable, np.int64),
        exact_unstable=np.asarray(exact_unstable, np.int64),
        rel_error=np.asarray(errors),
    )


@dataclass(frozen=True)
class TabulationProof:
    """The chosen grid, its tables and the evidence it passed.

    Attributes
    ----------
    grid, tables
        The chosen tabulation grid and the increment matrices at its nodes.
    check
        The check at all cell midpoints and the random interior points.
    rel_tol
        The interpolation error bound that was enforced (row-wise relative).
    history
        (counts, max error, unstable points) for every grid tried, in order.
    """

    grid: TabulationGrid
    tables: Matrix
    check: GridCheck
    rel_tol: float
    history: list[tuple[tuple[int, int, int], float, int]] = field(default_factory=list)


def _edge_midpoint_error(
    controller_fn: ControllerFn,
    grid: TabulationGrid,
    tables: Matrix,
    omega: float,
    lambda_: float,
    ts: float,
) -> list[float]:
    """Largest interpolation error at midpoints of edges along each axis (sampled edges)."""
    axes = grid.axes()
    errs = []
    for axis in range(3):
        worst = 0.0
        mids = 0.5 * (axes[axis][1:] + axes[axis][:-1])
        others = [ax[[0, len(ax) // 2, -1]] for ax in axes]
        for mval in mids:
            for p in others[(axis + 1) % 3]:
                for q in others[(axis + 2) % 3]:
                    rho = np.zeros(3)
                    rho[axis], rho[(axis + 1) % 3], rho[(axis + 2) % 3] = mval, p, q
                    exact = discretise_node(controller_fn(rho), omega, lambda_, ts)
                    worst = max(worst, row_relative_error(interpolate(tables, grid, rho), exact))
        errs.append(worst)
    return errs


def choose_grid(
    controller_fn: ControllerFn,
    box: Matrix,
    start_counts: Sequence[int],
    omega: float,
    lambda_: float,
    sample_period_s: float,
    *,
    rel_tol: float = 0.02,
    n_random: int = 32,
    seed: int = 0,
    max_nodes: int = 4000,
) -> TabulationProof:
    """Refine a uniform grid from ``start_counts`` until the stability and error checks pass.

    Parameters
    ----------
    controller_fn
        rho (physical units) -> continuous delayed controller (e.g. ``controller_at``).
    box
        (3, 2) design box, rows K [mmHg/(ml/h)], T [s], tau [s].
    start_counts
        Initial node counts (the synthesis grid's counts).
    rel_tol
        Row-wise relative interpolation error allowed at every checked point.
    n_random
        Seeded random interior points checked in addition to all cell midpoints.

    Raises
    ------
    RuntimeError
        If no grid within ``max_nodes`` passes.
    """
    box = np.asarray(box, float)
    rng = np.random.default_rng(seed)
    random_points = box[:, 0] + rng.random((n_random, 3)) * (box[:, 1] - box[:, 0])
    grid = TabulationGrid(
        tuple(box[:, 0]),
        tuple(box[:, 1]),
        tuple(int(c) for c in start_counts),  # type: ignore[arg-type]
    )
    history: list[tuple[tuple[int, int, int], float, int]] = []
    while True:
        tables = build_tables(controller_fn, grid, omega, lambda_, sample_period_s)
        edge = _edge_midpoint_error(controller_fn, grid, tables, omega, lambda_, sample_period_s)
        if max(edge) <= rel_tol:
            points = np.vstack([grid.cell_midpoints(), random_points])
            check = check_grid(controller_fn, grid, tables, points, omega, lambda_, sample_period_s)
            history.append(
                (grid.counts, float(np.max(check.rel_error)), int(np.sum(check.unstable > 0)))
            )
            if check.passed(rel_tol):
                return TabulationProof(grid, tables, check, rel_tol, history)
        else:
            history.append((grid.counts, max(edge), -1))
        nxt = grid.refined(int(np.argmax(edge)))
        if int(np.prod(nxt.counts)) > max_nodes:
            raise RuntimeError(
                f"no tabulation grid within {max_nodes} nodes passed (last {grid.counts}, "
                f"history {history})"
            )
        grid = nxt
