"""Where each decision matrix of the Theorem-3 synthesis LMI lives in the decision vector.

Every matrix (P̃, Q̃, R̃, X, Y, the transformed controller Â, Âd, B̂, Ĉ, Ĉd, Dk, γ, the per-node
levels γ_g and, in the "bound" rate mode, the slacks Z) is a :class:`Block` of basis coefficients;
:class:`Layout` packs and unpacks them (see :mod:`pressor.synthesis.families.theorem3.lmi` for the LMI
itself).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pressor.synthesis.problem import basis
from pressor.synthesis.problem.model import N_STATE, PlantDims

__all__ = ["Block", "Layout"]


@dataclass(frozen=True)
class Block:
    """One decision matrix: ``nb`` basis coefficients of a ``rows × cols`` matrix."""

    name: str
    rows: int
    cols: int
    sym: bool
    nb: int

    @property
    def size(self) -> int:
        per = self.rows * (self.rows + 1) // 2 if self.sym else self.rows * self.cols
        return per * self.nb


class Layout:
    """Positions of every decision matrix inside the decision vector."""

    def __init__(
        self,
        xy_dependence: str,
        rate_terms: str = "vertices",
        n_nodes: int = 0,
        plant_dims: PlantDims | None = None,
    ) -> None:
        nbx = basis.N_BASIS if xy_dependence in ("x", "xy") else 1
        nby = basis.N_BASIS if xy_dependence == "xy" else 1
        nb = basis.N_BASIS
        d = plant_dims or PlantDims(N_STATE, 3, 2, 2, False, False)
        n, n2, ny = d.n, 2 * d.n, d.ny
        self.n = n
        self.blocks = [
            Block("P", n2, n2, True, nb),
            Block("Q", n2, n2, True, 1),
            Block("R", n2, n2, True, 1),
            Block("X", n, n, True, nbx),
            Block("Y", n, n, True, nby),
            Block("Ah", n, n, False, nb),
            Block("Adh", n, n, False, nb),
            Block("Bh", n, ny, False, nb),
            Block("Ch", 1, n, False, nb),
            Block("Cdh", 1, n, False, nb),
            Block("Dk", 1, ny, False, nb),
            Block("gamma", 1, 1, False, 1),
        ]
        # per-node performance levels γ_g ≤ γ (the guarantee is γ = max γ_g)
        self.blocks.append(Block("gnode", 1, 1, False, max(n_nodes, 1)))
        if rate_terms == "bound":
            # node-local bounds Z_{g,i} ⪰ ±∂P̃/∂ρ̂_i (3 per node), see module docstring
            self.blocks.append(Block("Z", n2, n2, True, 3 * n_nodes))
        self.offsets: dict[str, int] = {}
        off = 0
        for b in self.blocks:
            self.offsets[b.name] = off
            off += b.size
        self.nvar = off
        self.by_name = {b.name: b for b in self.blocks}

    def free_mask(self, grid_points: tuple[int, int, int]) -> np.ndarray:
        """Boolean mask of the identifiable decision entries on a grid.

        The ½ρ̂i² coefficient (basis term 4 + i) of a parameter-dependent block other than P̃ is
        fixed to zero when axis i has only two nodes.
        """
        mask = np.ones(self.nvar, dtype=bool)
        for b in self.blocks:
            # P̃ keeps them: its derivative P_i1 + ρ̂_i P_i2 still differs between the two nodes
            if b.nb != basis.N_BASIS or b.name in ("P", "Z", "gnode"):
                continue
            per = b.size // b.nb
            for i in range(3):
                if grid_points[i] <= 2:
                    start = self.offsets[b.name] + (4 + i) * per
                    mask[start : start + per] = False
        return mask

    def unpack(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Decision vectors (J, nvar) -> name -> (J, nb, rows, cols) coefficient arrays."""
        x = np.atleast_2d(x)
        j = x.shape[0]
        out = {}
        for b in self.blocks:
            seg = x[:, self.offsets[b.name] : self.offsets[b.name] + b.size]
            if b.sym:
                iu = np.triu_indices(b.rows)
                m = np.zeros((j, b.nb, b.rows, b.rows))
                vals = seg.reshape(j, b.nb, -1)
                m[:, :, iu[0], iu[1]] = vals
                m[:, :, iu[1], iu[0]] = vals
            else:
                m = seg.reshape(j, b.nb, b.rows, b.cols)
            out[b.name] = m
        return out

    def pack(self, coeffs: dict[str, np.ndarray]) -> np.ndarray:
        """Inverse of :meth:`unpack` for one vector (coefficients (nb, rows, cols))."""
        x = np.zeros(self.nvar)
        for b in self.blocks:
            c = np.asarray(coeffs[b.name], dtype=float).reshape(b.nb, b.rows, b.cols)
            if b.sym:
                iu = np.triu_indices(b.rows)
                seg = c[:, iu[0], iu[1]].reshape(-1)
            else:
                seg = c.reshape(-1)
            x[self.offsets[b.name] : self.offsets[b.name] + b.size] = seg
        return x
