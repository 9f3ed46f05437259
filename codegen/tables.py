"""Tabulation grid for run-time interpolation, chosen and proven stable.

Multilinear interpolation of controller matrices tabulated at a coarse grid can destabilise loops
that the exactly reconstructed controller keeps stable (docs/notes/benchmarks.md, "Design
measurements"). So the tabulation grid is chosen over the design box,
independent of the synthesis grid (the artifact reconstructs the controller at any rho), refined
until every check passes:

1. the sampled frozen closed loop (FOPDT patient K/(T s + 1) e^(-tau s) under ZOH, the discrete
   controller with its delayed state read from a shift buffer, exactly what the generated step
   does) is stable at every cell midpoint and at seeded random interior points;
2. at the same points the interpolated increment matrix is within ``rel_tol`` (row-wise relative
   Frobenius error) of the matrix discretised from the exactly reconstructed controller.

The grid is a tensor grid with *non-uniform* nodes per axis (:class:`TabulationGrid`): K starts
geometric (uniform in log K — the controller inverts the plant gain, its matrices vary roughly like
1/K, so uniform-in-K nodes would have to be dense everywhere to be accurate at low K), and only the
intervals whose interpolation error is too large are bisected (:func:`choose_grid`). The run-time
step stays division-free: it finds the cell by a bounded binary search over the node list and
multiplies by the stored reciprocal of that cell's width. Clamping and rate limiting act on the
physical rho, never on a transformed coordinate.

The frozen-loop stability test is :mod:`pressor.codegen.frozen_loop`. The node matrices come from
:func:`pressor.codegen.discretise.discretise_node`, the same bits on every CPU; the checks here only decide
where nodes go.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from pressor.codegen.discretise import ContinuousController, discretise_node
from pressor.codegen.frozen_loop import frozen_loop_matrices, unstable_root_count

__all__ = [
    "GridCheck",
    "TabulationGrid",
    "TabulationProof",
    "build_tables",
    "check_grid",
    "choose_grid",
    "interpolate",
]


Matrix = NDArray[np.float64]
ControllerFn = Callable[[NDArray[np.float64]], ContinuousController]
#: Progress inside a long computation: (what, done, total). Called once per unit of work (a node, a
#: checked point), so thousands of times a second: the receiver decides what to show and when.
Report = Callable[[str, int, int], None]


def _silent(_what: str, _done: int, _total: int) -> None:
    return None


@dataclass(frozen=True)
class TabulationGrid:
    """A tensor grid over the box with (possibly non-uniform) sorted nodes per axis.

    Units per axis: K [mmHg/(ml/h)], T [s], tau [s]. The run-time step locates the cell by a bounded
    binary search over each axis's nodes and multiplies by the stored reciprocal of the cell width,
    so non-uniform nodes cost no division.
    """

    nodes_per_axis: tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]

    def __post_init__(self) -> None:
        for i, ax in enumerate(self.nodes_per_axis):
            if len(ax) < 2:
                raise ValueError(f"grid axis {i}: {len(ax)} nodes; need >= 2")
            if any(not b > a for a, b in zip(ax[:-1], ax[1:], strict=True)):
                raise ValueError(f"grid axis {i}: nodes {ax} must be strictly increasing")

    @classmethod
    def uniform(
        cls, lo: Sequence[float], hi: Sequence[float], counts: Sequence[int]
    ) -> TabulationGrid:
        """Uniform nodes, ``counts[i]`` per axis from ``lo[i]`` to ``hi[i]``."""
        return cls(
            tuple(  # type: ignore[arg-type]
                tuple(float(x) for x in np.linspace(lo[i], hi[i], int(counts[i]))) for i in range(3)
            )
        )

    @classmethod
    def start(cls, box: Matrix, counts: Sequence[int]) -> TabulationGrid:
        """Starting grid: K geometric (uniform in log K), T and tau uniform.

        The increment matrices vary roughly like 1/K (the plant gain is inverted), so equal steps in
        log K spread the interpolation error evenly where equal steps in K would crowd it at low K.
        """
        box = np.asarray(box, float)
        logs = np.linspace(math.log(box[0, 0]), math.log(box[0, 1]), int(counts[0]))
        # math.exp, not np.exp: numpy's float64 exp has an AVX-512 kernel of its own and uses the
        # C library's elsewhere, so the last bit of a node (where the tables are computed) could
        # depend on the vector width; math.exp is the C library's on every CPU.
        k = [math.exp(x) for x in logs.tolist()]
        k[0], k[-1] = float(box[0, 0]), float(box[0, 1])  # exact end points (clamp limits)
        rest = [np.linspace(box[i, 0], box[i, 1], int(counts[i])) for i in (1, 2)]
        return cls(tuple(tuple(float(x) for x in ax) for ax in (k, *rest)))  # type: ignore[arg-type]

    @property
    def lo(self) -> tuple[float, float, float]:
        """Lower box corner (first node per axis)."""
        return tuple(ax[0] for ax in self.nodes_per_axis)  # type: ignore[return-value]

    @property
    def hi(self) -> tuple[float, float, float]:
        """Upper box corner (last node per axis)."""
        return tuple(ax[-1] for ax in self.nodes_per_axis)  # type: ignore[return-value]

    @property
    def counts(self) -> tuple[int, int, int]:
        """Node count per axis."""
        return tuple(len(ax) for ax in self.nodes_per_axis)  # type: ignore[return-value]

    def axes(self) -> tuple[Matrix, Matrix, Matrix]:
        """The node coordinates per axis."""
        return tuple(np.asarray(ax, float) for ax in self.nodes_per_axis)  # type: ignore[return-value]

    def nodes(self) -> Matrix:
        """All nodes, shape (nK*nT*ntau, 3), K slowest, tau fastest (C order)."""
        a, b, c = self.axes()
        return np.stack(np.meshgrid(a, b, c, indexing="ij"), axis=-1).reshape(-1, 3)

    def cell_midpoints(self) -> Matrix:
        """Centres of all cells, shape (prod(counts-1), 3)."""
        mids = [0.5 * (ax[1:] + ax[:-1]) for ax in self.axes()]
        return np.stack(np.meshgrid(*mids, indexing="ij"), axis=-1).reshape(-1, 3)

    def locate(self, rho: Sequence[float]) -> tuple[list[int], list[float]]:
        """Cell index and fraction per axis of ``rho`` (clamped to the box)."""
        idx, frac = [], []
        for i, ax in enumerate(self.axes()):
            x = min(max(float(rho[i]), ax[0]), ax[-1])
            j = min(int(np.searchsorted(ax, x, side="right")) - 1, len(ax) - 2)
            idx.append(j)
            frac.append((x - ax[j]) / (ax[j + 1] - ax[j]))
        return idx, frac

    def bisected(self, axis: int, intervals: Sequence[int]) -> TabulationGrid:
        """The grid with the given intervals of ``axis`` split at their midpoints (nodes kept)."""
        ax = list(self.nodes_per_axis[axis])
        new = sorted(set(ax) | {0.5 * (ax[j] + ax[j + 1]) for j in intervals})
        axes = list(self.nodes_per_axis)
        axes[axis] = tuple(new)
        return TabulationGrid(tuple(axes))  # type: ignore[arg-type]


def build_tables(
    controller_fn: ControllerFn,
    grid: TabulationGrid,
    omega: float,
    lambda_: float,
    sample_period_s: float,
) -> Matrix:
    """Increment matrices at every node, shape ``(nK, nT, ntau, n_z, n_col)``."""
    return _NodeCache(controller_fn, omega, lambda_, sample_period_s).tables(grid)


def interpolate(tables: Matrix, grid: TabulationGrid, rho: Sequence[float]) -> Matrix:
    """Multilinear interpolation of ``tables`` at ``rho`` (clamped to the box, never extrapolated)."""
    idx, frac = grid.locate(rho)
    out = np.zeros(tables.shape[3:])
    for ca in (0, 1):
        wa = frac[0] if ca else 1.0 - frac[0]
        for cb in (0, 1):
            wb = frac[1] if cb else 1.0 - frac[1]
            for cc in (0, 1):
                wc = frac[2] if cc else 1.0 - frac[2]
                out += wa * wb * wc * tables[idx[0] + ca, idx[1] + cb, idx[2] + cc]
    return out


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


def check_grid(
    controller_fn: ControllerFn,
    grid: TabulationGrid,
    tables: Matrix,
    points: Matrix,
    omega: float,
    lambda_: float,
    sample_period_s: float,
    report: Report = _silent,
    what: str = "checked points",
) -> GridCheck:
    """Frozen-loop stability and interpolation error of ``tables`` at ``points``.

    ``report(what, done, len(points))`` is called after each point.
    """
    unstable, exact_unstable, errors = [], [], []
    for done, rho in enumerate(points, 1):
        approx = interpolate(tables, grid, rho)
        exact = discretise_node(controller_fn(rho), omega, lambda_, sample_period_s)
        unstable.append(unstable_root_count(frozen_loop_matrices(approx, rho, sample_period_s)))
        exact_unstable.append(
            unstable_root_count(frozen_loop_matrices(exact, rho, sample_period_s))
            if unstable[-1]
            else 0
        )
        errors.append(row_relative_error(approx, exact))
        report(what, done, len(points))
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


class _NodeCache:
    """Memo of discretised increment matrices by rho (nodes survive every refinement)."""

    def __init__(
        self, controller_fn: ControllerFn, omega: float, lambda_: float, ts: float
    ) -> None:
        self.fn, self.omega, self.lambda_, self.ts = controller_fn, omega, lambda_, ts
        self.memo: dict[tuple[float, float, float], Matrix] = {}

    def __call__(self, rho: Sequence[float]) -> Matrix:
        key = (float(rho[0]), float(rho[1]), float(rho[2]))
        m = self.memo.get(key)
        if m is None:
            m = discretise_node(self.fn(np.asarray(key)), self.omega, self.lambda_, self.ts)
            self.memo[key] = m
        return m

    def tables(self, grid: TabulationGrid, report: Report = _silent, what: str = "nodes") -> Matrix:
        nodes = grid.nodes()
        mats = []
        for done, rho in enumerate(nodes, 1):
            mats.append(self(rho))
            report(what, done, len(nodes))
        return np.asarray(mats).reshape(*grid.counts, *mats[0].shape)


def _edge_errors(
    exact: _NodeCache,
    grid: TabulationGrid,
    tables: Matrix,
    report: Report = _silent,
    what: str = "edge midpoints",
) -> list[Matrix]:
    """Per axis, per interval: the largest interpolation error at the interval's midpoint along
    every grid line of that axis (all combinations of the other axes' nodes)."""
    axes = grid.axes()
    counts = grid.counts
    total = sum((counts[a] - 1) * counts[(a + 1) % 3] * counts[(a + 2) % 3] for a in range(3))
    done = 0
    out = []
    for axis in range(3):
        o1, o2 = (axis + 1) % 3, (axis + 2) % 3
        mids = 0.5 * (axes[axis][1:] + axes[axis][:-1])
        errs = np.zeros(len(mids))
        for j, mval in enumerate(mids):
            for p in axes[o1]:
                for q in axes[o2]:
                    rho = np.zeros(3)
                    rho[axis], rho[o1], rho[o2] = mval, p, q
                    approx = interpolate(tables, grid, rho)
                    errs[j] = max(errs[j], row_relative_error(approx, exact(rho)))
                    done += 1
                    report(what, done, total)
        out.append(errs)
    return out


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
    edge_margin: float = 0.7,
    report: Report = _silent,
) -> TabulationProof:
    """Adaptively bisect a non-uniform grid until the stability and error checks pass.

    1. Start from :meth:`TabulationGrid.start` (K geometric, T and tau uniform) with the synthesis
       grid's counts.
    2. Bisect every axis interval whose edge-midpoint error (along all grid lines) exceeds
       ``edge_margin * rel_tol``; repeat until none does (cheap: 1-D checks only).
    3. Check every cell midpoint and ``n_random`` seeded interior points (error and frozen-loop
       stability, :func:`check_grid`). Each failing point bisects, in its cell, the interval of the
       axis with the largest edge error; go to 2.

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
    report
        Progress, ``(what, done, total)`` after every node and checked point; ``what`` names the
        refinement round, its grid (K x T x tau nodes) and the step (nodes discretised, edge
        midpoints, cell checks). The result does not depend on it.

    Raises
    ------
    RuntimeError
        If no grid within ``max_nodes`` passes.
    """
    box = np.asarray(box, float)
    rng = np.random.default_rng(seed)
    random_points = box[:, 0] + rng.random((n_random, 3)) * (box[:, 1] - box[:, 0])
    exact = _NodeCache(controller_fn, omega, lambda_, sample_period_s)
    grid = TabulationGrid.start(box, [max(2, int(c)) for c in start_counts])
    history: list[tuple[tuple[int, int, int], float, int]] = []

    def grow(nxt: TabulationGrid) -> TabulationGrid:
        if int(np.prod(nxt.counts)) > max_nodes:
            raise RuntimeError(
                f"no tabulation grid within {max_nodes} nodes passed (last {grid.counts}, "
                f"history {history})"
            )
        return nxt

    while True:
        head = f"round {len(history) + 1}, grid {'x'.join(str(c) for c in grid.counts)}"
        tables = exact.tables(grid, report, f"{head}: nodes")
        edge = _edge_errors(exact, grid, tables, report, f"{head}: edge midpoints")
        worst = max(float(np.max(e)) for e in edge)
        if worst > edge_margin * rel_tol:
            history.append((grid.counts, worst, -1))
            nxt = grid
            for axis in range(3):
                bad = np.nonzero(edge[axis] > edge_margin * rel_tol)[0]
                if len(bad):
                    nxt = nxt.bisected(axis, bad.tolist())
            grid = grow(nxt)
            continue
        points = np.vstack([grid.cell_midpoints(), random_points])
        check = check_grid(
            controller_fn,
            grid,
            tables,
            points,
            omega,
            lambda_,
            sample_period_s,
            report,
            f"{head}: cell checks",
        )
        failing = (check.rel_error > rel_tol) | ((check.unstable > 0) & (check.exact_unstable == 0))
        history.append(
            (grid.counts, float(np.max(check.rel_error)), int(np.sum(check.unstable > 0)))
        )
        if not failing.any():
            return TabulationProof(grid, tables, check, rel_tol, history)
        split: dict[int, set[int]] = {0: set(), 1: set(), 2: set()}
        for rho in points[failing]:
            idx, _ = grid.locate(rho)
            axis = int(np.argmax([edge[a][idx[a]] for a in range(3)]))
            split[axis].add(idx[axis])
        nxt = grid
        for axis, ivs in split.items():
            if ivs:
                nxt = nxt.bisected(axis, sorted(ivs))
        grid = grow(nxt)
