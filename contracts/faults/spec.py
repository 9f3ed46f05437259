"""Fault specifications: ``--fault KIND[:ARGS]`` texts and ``[[faults]]`` tables, validated.

Syntax: the package docstring (:mod:`pressor.contracts.faults`). Every bad value raises
:class:`FaultSpecError` naming the source, the field, the value and the allowed range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from pressor.contracts.faults.catalogue import (
    CATALOGUE,
    COMMON_PARAMS,
    FAULT_KINDS,
    FaultKind,
    Param,
)


class FaultSpecError(ValueError):
    """A bad fault specification; the message names source, field, value and allowed range."""


@dataclass(frozen=True)
class FaultSpec:
    """One scheduled fault.

    Attributes
    ----------
    kind
        A :data:`CATALOGUE` name.
    start_s, duration_s
        Window (s of sim time).
    seed
        Seed of its random draws.
    args
        Kind-specific arguments by name (all filled with defaults).
    index
        Position in the schedule (distinguishes two faults of one kind).
    """

    kind: str
    start_s: float
    duration_s: float
    seed: int = 0
    args: dict[str, float] = field(default_factory=dict)
    index: int = 0

    @property
    def info(self) -> FaultKind:
        return CATALOGUE[self.kind]

    def ticks(self, sample_period_s: float) -> tuple[int, int]:
        """``(first, end)`` ticks of the window, end exclusive (at least one tick)."""
        first = int(round(self.start_s / sample_period_s))
        n = max(1, int(round(self.duration_s / sample_period_s)))
        return first, first + n

    def to_cli(self) -> str:
        """The ``--fault`` text that parses back to this spec."""
        parts = [f"start_s={self.start_s!r}", f"duration_s={self.duration_s!r}"]
        parts.append(f"seed={self.seed}")
        parts += [f"{k}={v!r}" for k, v in self.args.items()]
        return f"{self.kind}:{','.join(parts)}"


def _number(src: str, key: str, text: Any, p: Param) -> float:
    if isinstance(text, bool):
        raise FaultSpecError(f"{src}: field '{key}' = {text!r} must be a number")
    try:
        v = float(text)
    except (TypeError, ValueError):
        raise FaultSpecError(
            f"{src}: field '{key}' = {text!r} must be a number in [{p.lo:g}, {p.hi:g}]"
        ) from None
    if not (math.isfinite(v) and p.lo <= v <= p.hi) or (p.integer and v != int(v)):
        kind = "an integer" if p.integer else "a number"
        raise FaultSpecError(
            f"{src}: field '{key}' = {text!r} outside [{p.lo:g}, {p.hi:g}] ({kind})"
        )
    return int(v) if p.integer else v


def make_spec(kind: str, values: dict[str, Any], src: str, index: int = 0) -> FaultSpec:
    """Validate ``values`` (argument name -> value) for ``kind`` into a :class:`FaultSpec`.

    Raises
    ------
    FaultSpecError
        Naming ``src``, the field, the value and the allowed range.
    """
    if kind not in CATALOGUE:
        raise FaultSpecError(f"{src}: field 'kind' = {kind!r} must be one of {list(FAULT_KINDS)}")
    info = CATALOGUE[kind]
    allowed = {p.name: p for p in (*COMMON_PARAMS, *info.params)}
    out: dict[str, float] = {}
    for key, text in values.items():
        if key not in allowed:
            raise FaultSpecError(
                f"{src}: field '{key}' = {text!r} unknown for {kind}; allowed {sorted(allowed)}"
            )
        out[key] = _number(src, key, text, allowed[key])
    start = out.pop("start_s", info.default_start_s)
    duration = out.pop("duration_s", info.default_duration_s)
    seed = int(out.pop("seed", 0))
    args = {p.name: out.get(p.name, p.default) for p in info.params}
    return FaultSpec(kind, float(start), float(duration), seed, args, index)


def parse_fault(text: str, index: int = 0, src: str = "--fault") -> FaultSpec:
    """Parse ``KIND[:ARGS]`` (syntax: :mod:`pressor.contracts.faults`)."""
    kind, _, rest = text.strip().partition(":")
    values: dict[str, Any] = {}
    positional = ("start_s", "duration_s")
    n_pos = 0
    for item in filter(None, (s.strip() for s in rest.replace(":", ",").split(","))):
        key, eq, value = item.partition("=")
        if not eq:
            if n_pos >= len(positional):
                raise FaultSpecError(
                    f"{src} {text}: field 'args' = {item!r} at most two bare numbers"
                    " (start_s, duration_s); use key=value"
                )
            key, value = positional[n_pos], item
            n_pos += 1
        values[key.strip()] = value.strip()
    return make_spec(kind, values, f"{src} {text}", index)


def parse_faults(texts: list[str] | tuple[str, ...]) -> list[FaultSpec]:
    """Parse every ``--fault`` of a command line (indices in order)."""
    return [parse_fault(t, i) for i, t in enumerate(texts)]


def parse_fault_table(table: Any, file: str, i: int, index: int = 0) -> FaultSpec:
    """One ``[[faults]]`` table of a scenario TOML (``kind = "..."`` plus arguments)."""
    src = f"{file}: faults[{i}]"
    if not isinstance(table, dict):
        raise FaultSpecError(f"{src}: must be a table [[faults]]")
    values = dict(table)
    kind = values.pop("kind", None)
    if not isinstance(kind, str):
        raise FaultSpecError(f"{src}: field 'kind' = {kind!r} must be one of {list(FAULT_KINDS)}")
    return make_spec(kind, values, src, index)
