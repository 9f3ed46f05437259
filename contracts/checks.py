"""One range check and one message shape for every package's argument and field checks.

It lives in ``contracts`` because that is the one package every other may import (synthesis,
runtime, sim alike; ``tests/test_layers.py``): a checker anywhere higher would need a new
arrow, or a copy. The message names the field, its value and the allowed range, with the range's
open or closed ends and its unit::

    q_b = -1.0: must be a finite number > 0
    --pump-max-ml-h = 0.0: must be a finite number in (0, 10000] ml/h
    --patients = 0: must be an integer in [1, 100000]

Callers keep their own context by the name they pass (``"field 'solver.lambda2'"``) and the error
they raise (``error=lambda msg: ConfigError(f"{source}: {msg}")``).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable

__all__ = ["allowed_range", "check_int_range", "check_range"]


def _num(x: float) -> str:
    """``x`` short (``0``, ``1e-05``, ``10000``) where that reads back as ``x``, else its repr."""
    if isinstance(x, int):
        return str(x)
    short = f"{x:g}"
    return short if float(short) == x else repr(x)


def allowed_range(
    lo: float = -math.inf,
    hi: float = math.inf,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    unit: str = "",
) -> str:
    """The range in words: ``in [lo, hi] unit``, or ``> lo unit`` (``>=``, ``<``, ``<=``) when one
    end is infinite, or ``""`` when both are.

    Parameters
    ----------
    lo, hi
        The ends (±inf: no end).
    lo_open, hi_open
        Whether the end itself is excluded.
    unit
        Appended after a space when given.
    """
    if math.isinf(hi):
        if math.isinf(lo):
            return ""  # no end: any finite number
        text = f"{'>' if lo_open else '>='} {_num(lo)}"
    elif math.isinf(lo):
        text = f"{'<' if hi_open else '<='} {_num(hi)}"
    else:
        text = f"in {'(' if lo_open else '['}{_num(lo)}, {_num(hi)}{')' if hi_open else ']'}"
    return f"{text} {unit}" if unit else text


def check_range(
    name: str,
    value: object,
    lo: float = -math.inf,
    hi: float = math.inf,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    unit: str = "",
    error: Callable[[str], Exception] = ValueError,
) -> float:
    """``value`` as a float if it is a finite real number (not a bool) within the range.

    Parameters
    ----------
    name
        What the value is, as the message should name it (an argument, ``--option`` or
        ``field 'table.key'``).
    value
        The value to check.
    lo, hi, lo_open, hi_open, unit
        The allowed range (:func:`allowed_range`).
    error
        Builds the exception from the message (default :class:`ValueError`); a caller adds its
        context here (the file a field came from) or picks its error type.

    Raises
    ------
    Exception
        ``error("<name> = <value!r>: must be a finite number <range>")`` otherwise.
    """
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool)
    if ok:
        v = float(value)  # type: ignore[arg-type]
        ok = math.isfinite(v) and (v > lo if lo_open else v >= lo)
        ok = ok and (v < hi if hi_open else v <= hi)
    if not ok:
        allowed = allowed_range(lo, hi, lo_open=lo_open, hi_open=hi_open, unit=unit)
        raise error(f"{name} = {value!r}: must be a finite number {allowed}".rstrip())
    return v


def check_int_range(
    name: str,
    value: object,
    lo: int,
    hi: int,
    *,
    unit: str = "",
    error: Callable[[str], Exception] = ValueError,
) -> int:
    """``value`` if it is an integer (not a bool) in [``lo``, ``hi``] (exact: seeds reach 2**63).

    Parameters
    ----------
    name, error
        As for :func:`check_range`.
    value
        The value to check.
    lo, hi
        The closed range.
    unit
        Appended to the range in the message when given.

    Raises
    ------
    Exception
        ``error("<name> = <value!r>: must be an integer in [lo, hi]")`` otherwise.
    """
    if isinstance(value, numbers.Integral) and not isinstance(value, bool) and lo <= value <= hi:
        return int(value)
    raise error(f"{name} = {value!r}: must be an integer {allowed_range(lo, hi, unit=unit)}")
