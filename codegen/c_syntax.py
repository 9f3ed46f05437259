"""C99 spelling shared by the C emitters: the name prefixes and exact floating literals.

Floating constants are written in decimal, the shortest digits that round-trip to the same IEEE-754
double (Python's ``repr``), so ``120.0`` reads as 120.0 and not ``0x1.e000000000000p+6``. A C
compiler that rounds decimal constants correctly (gcc and clang do; C99 6.4.4.2 allows the
neighbouring value as well) reads back the very double Python wrote, which is what keeps the C step
bit-exact with the Python reference (the codegen tests check it on the compiled library). Where a
named constant's decimal is not the binary value itself (``0.1``), the exact hexadecimal value
follows in a comment, so a reader can check the bits without trusting the conversion; the tables'
coefficients (tens of thousands) go without, several to a line, their bits checked by the tests
against the Python module's instead.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from decimal import Decimal

__all__ = ["P", "PU", "c_double", "c_double_array", "c_double_commented", "exact_note"]

#: prefixes of every generated C identifier (P) and macro (PU)
P = "lpvmap_"
PU = "LPVMAP_"


def c_double(x: float) -> str:
    """Shortest decimal C99 floating literal that round-trips to the double ``x``.

    Raises
    ------
    ValueError
        ``x`` is not finite (C99 has no literal for it).
    """
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"no C literal for {x!r}; allowed finite values")
    return repr(x)  # always has '.' or 'e': a floating constant, never an integer one


def exact_note(x: float) -> str:
    """The exact hexadecimal value of ``x`` when its shortest decimal is not exactly ``x``, else
    ``""`` (``0.1`` -> ``"0x1.999999999999ap-4"``, ``120.0`` -> ``""``)."""
    x = float(x)
    return "" if Decimal(repr(x)) == Decimal(x) else x.hex()


def c_double_commented(x: float) -> str:
    """:func:`c_double`, followed by ``/* <hex> */`` when the decimal is not exactly ``x``."""
    note = exact_note(x)
    return c_double(x) + (f"  /* {note} */" if note else "")


#: table coefficients written on one line (a row of a node's block stays readable at 100 columns)
PER_LINE = 4


def c_double_array(values: Iterable[float], indent: str = "    ") -> str:
    """The initialiser body of a double array: :data:`PER_LINE` elements a line, decimal only
    (module docstring: the tables' bits are checked by the tests, not noted).

    Returns the lines between the braces (each ending in a comma but the last), joined by
    newlines, for ``{\\n<body>\\n}``.
    """
    lits = [c_double(v) for v in values]
    rows = [", ".join(lits[i : i + PER_LINE]) for i in range(0, len(lits), PER_LINE)]
    return ",\n".join(indent + row for row in rows)
