"""Which of Clarabel's KKT solvers the synthesis solves use, in which order (no numpy here).

Clarabel factorises the KKT system of each interior-point iteration with the backend named by its
``direct_solve_method`` setting. :func:`pressor.synthesis.solver.conic.solve_conic` tries the attempts of
the current chain in order while a solve ends in a numerical failure; :func:`kkt_chain` sets the
chain for a block of code (a context variable, so it follows the code that runs the solve, not a
global); ``pressor synth --kkt`` and ``pressor verify --kkt`` take it as text
(:func:`parse_kkt_chain`). This module imports nothing heavy so that the commands can build their
help before numpy loads.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "DEFAULT_KKT_CHAIN",
    "KKT_METHODS",
    "KktAttempt",
    "current_kkt_chain",
    "kkt_chain",
    "parse_kkt_chain",
]

#: Clarabel's direct KKT solvers this project uses (``direct_solve_method`` values)
KKT_METHODS = ("faer", "qdldl")


@dataclass(frozen=True)
class KktAttempt:
    """One attempt of a chain: a KKT backend and any further Clarabel settings for it.

    Attributes
    ----------
    method
        ``direct_solve_method``, one of :data:`KKT_METHODS`.
    settings
        Further Clarabel settings by name for this attempt only (default none).
    """

    method: str
    settings: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.method not in KKT_METHODS:
            raise ValueError(f"KKT method {self.method!r} not one of {list(KKT_METHODS)}")

    def __str__(self) -> str:
        extra = ", ".join(f"{k}={v!r}" for k, v in self.settings.items())
        return f"{self.method}({extra})" if extra else self.method


#: the attempts tried in order until one ends without a numerical failure: Clarabel's default
#: backend (faer: supernodal, multithreaded, SIMD kernels chosen by CPU feature), then qdldl (a
#: simplicial LDL' with its own ordering and no SIMD dispatch; ~10x slower on the design)
DEFAULT_KKT_CHAIN: tuple[KktAttempt, ...] = (KktAttempt("faer"), KktAttempt("qdldl"))
_CHAIN: ContextVar[tuple[KktAttempt, ...]] = ContextVar(
    "pressor_kkt_chain", default=DEFAULT_KKT_CHAIN
)


@contextmanager
def kkt_chain(attempts: Sequence[str | KktAttempt]) -> Iterator[tuple[KktAttempt, ...]]:
    """Solve with the KKT ``attempts`` (tried in this order) inside the ``with`` block.

    Parameters
    ----------
    attempts
        One or more backends, by name (one of :data:`KKT_METHODS`) or as :class:`KktAttempt`;
        a single one forces it (no fallback).

    Raises
    ------
    ValueError
        An empty chain or an unknown name.
    """
    chain = tuple(a if isinstance(a, KktAttempt) else KktAttempt(str(a)) for a in attempts)
    if not chain:
        raise ValueError(f"KKT chain: at least one of {list(KKT_METHODS)} needed")
    token = _CHAIN.set(chain)
    try:
        yield chain
    finally:
        _CHAIN.reset(token)


def parse_kkt_chain(text: str) -> tuple[KktAttempt, ...]:
    """``"faer,qdldl"`` -> the attempts faer then qdldl.

    Raises
    ------
    ValueError
        Naming the text and the allowed names (an empty, unknown or repeated name).
    """
    names = [part.strip() for part in text.split(",")]
    if any(m not in KKT_METHODS for m in names) or len(set(names)) != len(names):
        raise ValueError(
            f"KKT chain {text!r}: comma-separated distinct names from {list(KKT_METHODS)} needed"
        )
    return tuple(KktAttempt(m) for m in names)


def current_kkt_chain() -> tuple[KktAttempt, ...]:
    """The attempts :func:`pressor.synthesis.solver.conic.solve_conic` makes, in order (:func:`kkt_chain`
    sets them)."""
    return _CHAIN.get()
