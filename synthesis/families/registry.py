"""The controller families: one registry, each family one object registered by name.

A design names its family (design TOML ``[controller]``, artifact metadata ``controller``) as a
:class:`ControllerFamily`: the ``structure`` (a registered name) and its one optional parameter,
``loop_gain``. Everything that differs between families — coefficient shapes, controller order,
the design stage, check (a) of ``pressor verify``, the controller at a frozen ρ — is a method of the
family's :class:`Family` object, defined in the family's own module and looked up here by name
(:func:`family_named`, or ``ControllerFamily.impl``). Callers never test the name.

Registered families:

* ``"smith"`` (:mod:`pressor.synthesis.families.smith.family`, the shipped one): the scheduled Smith
  predictor + PI in closed form, certified by the Wirtinger analysis LMI in K-scaled coordinates.
* ``"theorem3"`` (:mod:`pressor.synthesis.families.theorem3.family`, the alternative): the full-order
  controller synthesised by the paper's Theorem-3 LMIs. A design file or an artifact without a
  ``controller`` entry is this family (:data:`DEFAULT_STRUCTURE`), so it is never stored.

This module imports no family module at import time (the registry loads them on first lookup), so
the config reader and the artifact loader can import it without a cycle.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:  # numpy only annotates here: the CLIs import this module before parsing
    import numpy as np

    from pressor.synthesis.artifact import ControllerArtifact
    from pressor.synthesis.certificates.interface import AnalysisResult
    from pressor.synthesis.problem.closed_loop import DelaySystem
    from pressor.synthesis.problem.config import DesignConfig
    from pressor.synthesis.problem.reconstruct import DelayedController

__all__ = [
    "DEFAULT_STRUCTURE",
    "LOOP_GAIN_RANGE",
    "ControllerFamily",
    "Designed",
    "Family",
    "SynthRequest",
    "family_named",
    "structures",
]

#: the family of a design or artifact that names none (never stored, see module doc)
DEFAULT_STRUCTURE = "theorem3"
#: registered name -> the module whose ``FAMILY`` attribute is the family object
_MODULES: dict[str, str] = {
    "theorem3": "pressor.synthesis.families.theorem3.family",
    "smith": "pressor.synthesis.families.smith.family",
    "smith-pe": "pressor.synthesis.families.smith.pe_family",
}
#: allowed ``loop_gain`` (dimensionless) of a family that takes one: lower bound excluded
LOOP_GAIN_RANGE = (0.0, 10.0)

Progress = Callable[[str], None]


@dataclass(frozen=True)
class SynthRequest:
    """What ``pressor synth`` asks of a family's design stage besides the config.

    Attributes
    ----------
    given
        The family-specific options the user gave (``--lambda-search``, …); the CLI has already
        checked they are among the family's :attr:`Family.synth_options`.
    lambda_search
        Run the (λ2, λ3) line search first.
    jobs
        Local worker processes of that search.
    scheduler
        Dask scheduler address of that search (None: local).
    """

    given: frozenset[str] = frozenset()
    lambda_search: bool = False
    jobs: int = 1
    scheduler: str | None = None


@dataclass
class Designed:
    """A design stage's outcome: the artifact (None: not certified / failed) and what to print.

    Attributes
    ----------
    artifact
        The certified artifact, or None.
    summary
        Lines for stdout (γ, status, …), in order.
    notes
        Lines for stderr printed even with ``--quiet`` (the result depends on them).
    failure
        One line for stderr when ``artifact`` is None.
    """

    artifact: ControllerArtifact | None
    summary: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    failure: str | None = None


class Family(Protocol):
    """What every controller family provides (one object per family, registered by ``name``)."""

    #: the registered name, stored in designs and artifacts
    name: str
    #: whether the family takes the ``loop_gain`` parameter (required then, absent otherwise)
    takes_loop_gain: bool
    #: the ``pressor synth`` options only this family uses (a usage error for the others)
    synth_options: frozenset[str]
    #: whether the generated law absorbs a change of K in its integral on a log-K scale (the
    #: bumpless integral, whose rate term the family's certificate carries)
    bumpless_log_k: bool

    def controller_order(self, n_plant: int) -> int:
        """States of the controller for a generalised plant of ``n_plant`` states."""
        ...

    def coefficient_shapes(self, n_plant: int, ny: int) -> dict[str, tuple[tuple[int, ...], ...]]:
        """The artifact's ``coef_<name>`` arrays: name -> every allowed shape."""
        ...

    def design(self, cfg: DesignConfig, request: SynthRequest, progress: Progress) -> Designed:
        """The design stage of ``pressor synth`` (certify / synthesise, package the artifact)."""
        ...

    def controller_at(self, artifact: ControllerArtifact, rho: np.ndarray) -> DelayedController:
        """The controller at ρ (physical, inside the box: the caller has checked and clipped)."""
        ...

    def analysis(
        self,
        artifact: ControllerArtifact,
        systems: list[DelaySystem],
        mesh: np.ndarray,
        centre: tuple[DelaySystem, np.ndarray],
        p_dependence: str,
        progress: Progress,
    ) -> AnalysisResult:
        """Check (a) of ``pressor verify``: the family's analysis LMI over the dense ``mesh``.

        ``systems`` are the frozen closed loops at the rows of ``mesh``; ``centre`` the loop at the
        nominal ρ (clipped to the box) and that ρ.
        """
        ...


def structures() -> tuple[str, ...]:
    """The registered family names (the allowed ``[controller] structure`` values)."""
    return tuple(_MODULES)


def family_named(name: str) -> Family:
    """The registered family ``name``.

    Raises
    ------
    ValueError
        If no family of that name is registered.
    """
    if name not in _MODULES:
        raise ValueError(f"controller.structure = {name!r}: must be one of {structures()}")
    fam: Family = importlib.import_module(_MODULES[name]).FAMILY
    return fam


@dataclass(frozen=True)
class ControllerFamily:
    """Which controller a design carries (the stored form: a name and its parameter).

    Attributes
    ----------
    structure
        A registered family name (:func:`structures`); default :data:`DEFAULT_STRUCTURE`.
    loop_gain
        K·Kc = T/λ (dimensionless, in (0, 10]) for a family that takes it; None otherwise.
    """

    structure: str = DEFAULT_STRUCTURE
    loop_gain: float | None = None

    def __post_init__(self) -> None:
        impl = family_named(self.structure)
        lg = self.loop_gain
        if not impl.takes_loop_gain:
            if lg is not None:
                raise ValueError(
                    f"controller.loop_gain = {lg!r}: not taken by structure {self.structure!r}"
                )
            return
        lo, hi = LOOP_GAIN_RANGE
        if (
            isinstance(lg, bool)
            or not isinstance(lg, int | float)
            or not (math.isfinite(lg) and lo < lg <= hi)
        ):
            raise ValueError(
                f"controller.loop_gain = {lg!r}: must be a number in ({lo:g}, {hi:g}] "
                f"for {self.structure!r}"
            )

    @property
    def impl(self) -> Family:
        """The registered family object of :attr:`structure`."""
        return family_named(self.structure)

    @property
    def is_default(self) -> bool:
        """True for the family a design or artifact without a ``controller`` entry means."""
        return self.structure == DEFAULT_STRUCTURE

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the artifact's ``controller`` metadata entry)."""
        return {"structure": self.structure, "loop_gain": self.loop_gain}

    @classmethod
    def from_metadata(cls, meta: Mapping[str, Any]) -> ControllerFamily:
        """The family of an artifact's metadata (no ``controller`` entry: the default family).

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
