"""What both emitters share: the emit specification and the numbers derived from it.

The Python module (:mod:`pressor.codegen.emit_python`) and the C target (:mod:`pressor.codegen.emit_c`) compute
with the same constants (:func:`derived_constants`), store the same coefficients
(:func:`nonzero_entries`) and address the same cell corners (:func:`corner_offsets`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pressor.codegen.fixed_point import FixedPointPlan
from pressor.contracts.drug import DEFAULT_BINDING, DrugBinding

__all__ = ["EmitSpec", "corner_offsets", "derived_constants", "nonzero_entries", "py_float"]


@dataclass(frozen=True)
class EmitSpec:
    """Everything the emitters need besides the fixed-point plan.

    Attributes
    ----------
    nodes
        Tabulation grid nodes per axis, sorted, possibly non-uniform (physical units: K
        mmHg/(ml/h), T s, tau s).
    rate_bounds
        |dK/dt| (1/s units of K), |dT/dt| (s/s), |dtau/dt| (s/s).
    sample_period_s, max_rate_ml_h
        Ts and pump limit.
    n_k
        Controller order.
    artifact_sha256, content_hash, command
        Provenance for the header.
    budgets
        Name -> (value, description) error budgets stated in the header.
    reference
        (lambda_s, pump_fraction, k_min) of the two-degree-of-freedom prefilter
        (:mod:`pressor.synthesis.problem.reference`), or None: the controller then sees the target directly.
    drug
        The drug and syringe concentration (µg/ml) the gains are for.
    k_rate_relative
        False: the K rate bound (``rate_bounds[0]``) is |dK/dt|; True: it bounds the fall of
        ln K (1/s) and ``k_rate_up_per_s`` its rise (the limiter is then multiplicative).
    k_rate_up_per_s
        The bound on the rise of ln K (1/s) when ``k_rate_relative`` (None: ``rate_bounds[0]``).
    reference_lag_s
        The prefilter model's fixed lag T (s), or None: the feedback's scheduled T.
    bumpless
        Emit the Smith law's bumpless integral (:mod:`pressor.synthesis.families.smith.law`): when the
        scheduled K moves from K to K', x_e <- ρ x_e + (1 - ρ)(τ(ŷ + ŷ(t - τ))/2 - T e_p),
        ρ = K'/K (needs a two-state controller, x_k = [û, ŷ]).
    population
        The patients' sensitivity range in mmHg per µg/kg/min (the design's ``[population]``),
        or None.
    """

    nodes: tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]
    rate_bounds: tuple[float, float, float]
    sample_period_s: float
    max_rate_ml_h: float
    n_k: int
    artifact_sha256: str
    content_hash: str
    command: str
    budgets: dict[str, tuple[float, str]]
    reference: tuple[float, float, float] | None = None
    drug: DrugBinding = DEFAULT_BINDING
    k_rate_relative: bool = False
    k_rate_up_per_s: float | None = None
    reference_lag_s: float | None = None
    bumpless: bool = False
    population: tuple[float, float] | None = None

    @property
    def lo(self) -> tuple[float, float, float]:
        """Lower box corner."""
        return tuple(ax[0] for ax in self.nodes)  # type: ignore[return-value]

    @property
    def hi(self) -> tuple[float, float, float]:
        """Upper box corner."""
        return tuple(ax[-1] for ax in self.nodes)  # type: ignore[return-value]

    @property
    def counts(self) -> tuple[int, int, int]:
        """Nodes per axis."""
        return tuple(len(ax) for ax in self.nodes)  # type: ignore[return-value]

    def inv_widths(self, axis: int) -> list[float]:
        """Reciprocal cell widths of ``axis`` (computed once, offline)."""
        ax = self.nodes[axis]
        return [1.0 / (ax[j + 1] - ax[j]) for j in range(len(ax) - 1)]


def py_float(x: float) -> str:
    """Exact round-trip literal of a float."""
    return repr(float(x))


def derived_constants(spec: EmitSpec, plan: FixedPointPlan) -> dict[str, float | int]:
    """Constants shared by both emitters (so Python and C compute with the same numbers)."""
    ts = spec.sample_period_s
    nz = spec.n_k + 2
    c: dict[str, float | int] = {
        "NBUF": int(math.ceil(spec.hi[2] / ts - 1e-9)) + 1,
        "INV_TS": 1.0 / ts,
        "DMAX_SAMPLES": spec.hi[2] / ts,
        "E_LIM": plan.e_scale,
        "E_TO_S": 1.0 / plan.e_scale,
        "E_TO_Q": 2.0**31 / plan.e_scale,
        "U_SCALE": float(plan.state_scale[spec.n_k]),
        "U_MAX_S": spec.max_rate_ml_h / float(plan.state_scale[spec.n_k]),
        "U_MAX_Q": int(math.floor(spec.max_rate_ml_h / plan.state_scale[spec.n_k] * 2.0**31)),
        "U_Q_TO_ML_H": float(plan.state_scale[spec.n_k]) / 2.0**31,
        "XE_GAIN": plan.xe_gain,
        "XE_Q": plan.xe_q,
        "XE_SHIFT": plan.xe_shift,
        "W": plan.weight_bits,
        "WONE": float(1 << plan.weight_bits),
    }
    for i in range(3):
        c[f"LO{i}"] = float(spec.lo[i])
        c[f"HI{i}"] = float(spec.hi[i])
        c[f"N{i}"] = int(spec.counts[i])
        c[f"RSTEP{i}"] = float(spec.rate_bounds[i] * ts)
    if spec.k_rate_relative:
        up = spec.rate_bounds[0] if spec.k_rate_up_per_s is None else spec.k_rate_up_per_s
        c["KDN"] = math.exp(-spec.rate_bounds[0] * ts)
        c["KUP"] = math.exp(up * ts)
    if spec.bumpless:
        s1, s3 = float(plan.state_scale[1]), float(plan.state_scale[spec.n_k + 1])
        c["BL_S1"] = s1
        c["BL_S3"] = s3
        c["BL_INV_S3"] = 1.0 / s3
        c["BL_Q1"] = s1 / 2.0**31
        c["BL_Q3"] = s3 / 2.0**31
        c["BL_INV_Q3"] = 2.0**31 / s3
        c["BL_QE"] = plan.e_scale / 2.0**31
    for i in range(nz - 1):
        c[f"F{i}"] = int(plan.row_shift[i])
    if spec.reference is not None:
        lam, frac, k_min = spec.reference
        c["PF_KLO"] = float(k_min)
        c["PF_INV_LAMBDA"] = 1.0 / lam
        c["PF_UMAX"] = frac * spec.max_rate_ml_h
        c["PF_TS"] = float(ts)
        c["PF_SIXTH"] = 1.0 / 6.0
        c["INV_U_SCALE"] = 1.0 / float(plan.state_scale[spec.n_k])
        c["U_TO_Q"] = 2.0**31 / float(plan.state_scale[spec.n_k])
        if spec.reference_lag_s is not None:
            c["PF_TLAG"] = float(spec.reference_lag_s)
    return c


def nonzero_entries(plan: FixedPointPlan) -> list[tuple[int, int]]:
    """(row, col) of the coefficients that are non-zero at some node (others are skipped)."""
    nzmask = np.any(plan.scaled_tables != 0.0, axis=(0, 1, 2))
    return [(int(i), int(j)) for i, j in zip(*np.nonzero(nzmask), strict=True)]


def corner_offsets(counts: Sequence[int]) -> list[int]:
    """Flat-index offsets of the 8 cell corners, corner c = (cK, cT, ctau) as bits 2, 1, 0."""
    _, nt, na = counts
    return [ck * nt * na + ct * na + ca for ck in (0, 1) for ct in (0, 1) for ca in (0, 1)]
