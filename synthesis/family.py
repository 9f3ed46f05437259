"""The controller family of a design: which law the artifact carries and how it is certified.

Two families (design TOML ``[controller]``, artifact metadata ``controller``):

* ``"theorem3"`` — the full-order controller of the paper's Theorem 3, synthesised by the LMIs of
  :mod:`synthesis.lmi` (Jensen functional); the artifact's coefficients are the decision variables
  and the controller is reconstructed from them (:mod:`synthesis.reconstruct`). A design file or
  an artifact without a ``controller`` entry is this family (every artifact written before the
  field existed).
* ``"smith"`` — the scheduled Smith predictor + PI of :class:`synthesis.smith_lpv.SmithLPV` with
  one parameter, ``loop_gain`` = K·Kc = T/λ (dimensionless, in (0, 10]); the law is fixed in
  closed form, so there is no synthesis LMI: the design stage is the Wirtinger-based analysis of
  :mod:`synthesis.analysis_wirtinger` in K-scaled coordinates (:mod:`synthesis.k_scaling`) on the
  design grid, and the artifact stores its certificate (``P``, ``S``, ``R`` and the state
  ``transform`` it lives in, all in those coordinates, see :func:`smith_coef_shapes`).

This module is a leaf of the synthesis package (numpy only): the config reader, the artifact
loader and the reconstruction share its names, ranges and shapes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

__all__ = [
    "LOOP_GAIN_RANGE",
    "SMITH_ORDER",
    "STRUCTURES",
    "ControllerFamily",
    "smith_coef_shapes",
]

STRUCTURES = ("theorem3", "smith")
#: allowed loop gain K·Kc of the "smith" family (dimensionless): lower bound excluded
LOOP_GAIN_RANGE = (0.0, 10.0)
#: controller states of the "smith" family: û (ml/h, the model's filter state) and ŷ (mmHg)
SMITH_ORDER = 2
#: basis terms of the certificate's P(ρ) (quadratic in ρ̂: 1, ρ̂_i, ρ̂_i²/2)
SMITH_P_TERMS = 7


@dataclass(frozen=True)
class ControllerFamily:
    """Which controller a design carries.

    Attributes
    ----------
    structure
        "theorem3" (synthesised, the default) or "smith" (closed-form, certified by analysis).
    loop_gain
        For "smith" only: K·Kc = T/λ, dimensionless, in (0, 10]; None for "theorem3".
    """

    structure: str = "theorem3"
    loop_gain: float | None = None

    def __post_init__(self) -> None:
        if self.structure not in STRUCTURES:
            raise ValueError(
                f"controller.structure = {self.structure!r}: must be one of {STRUCTURES}"
            )
        if self.structure == "theorem3":
            if self.loop_gain is not None:
                raise ValueError(
                    f"controller.loop_gain = {self.loop_gain!r}: only for structure 'smith'"
                )
            return
        lg = self.loop_gain
        lo, hi = LOOP_GAIN_RANGE
        if (
            isinstance(lg, bool)
            or not isinstance(lg, int | float)
            or not (math.isfinite(lg) and lo < lg <= hi)
        ):
            raise ValueError(
                f"controller.loop_gain = {lg!r}: must be a number in ({lo:g}, {hi:g}] for 'smith'"
            )

    @property
    def is_smith(self) -> bool:
        """True for the closed-form Smith family."""
        return self.structure == "smith"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the artifact's ``controller`` metadata entry)."""
        return {"structure": self.structure, "loop_gain": self.loop_gain}

    @classmethod
    def from_metadata(cls, meta: dict[str, Any]) -> ControllerFamily:
        """The family of an artifact's metadata (no ``controller`` entry: "theorem3").

        Raises
        ------
        ValueError
            A ``controller`` entry that is not ``{structure, loop_gain}`` or has a bad value.
        """
        entry = meta.get("controller")
        if entry is None:
            return cls()
        if not isinstance(entry, dict) or set(entry) != {"structure", "loop_gain"}:
            raise ValueError("controller must have exactly the keys ['loop_gain', 'structure']")
        lg = entry["loop_gain"]
        return cls(str(entry["structure"]), None if lg is None else lg)


def smith_coef_shapes(n_plant: int) -> dict[str, tuple[int, ...]]:
    """The "smith" artifact's coefficients: the Wirtinger certificate, name -> shape.

    The closed loop has ``n = n_plant + SMITH_ORDER`` states; ``P`` (7, 2n, 2n) are the basis terms
    of P(ρ) on ξ = [x; ∫x], ``S``, ``R`` (n, n) the integral terms, all divided by γ, and
    ``transform`` (n, n) the state coordinates they live in (scaled time, see
    :func:`synthesis.analysis_wirtinger.analyse_wirtinger`).
    """
    n = n_plant + SMITH_ORDER
    return {"P": (SMITH_P_TERMS, 2 * n, 2 * n), "S": (n, n), "R": (n, n), "transform": (n, n)}
