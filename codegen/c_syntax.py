"""C99 spelling shared by the C emitters: the name prefixes and exact floating literals."""

from __future__ import annotations

__all__ = ["P", "PU", "c_double"]

#: prefixes of every generated C identifier (P) and macro (PU)
P = "lpvmap_"
PU = "LPVMAP_"


def c_double(x: float) -> str:
    """Exact C99 hexadecimal floating literal."""
    x = float(x)
    if x == 0.0:
        return "0.0"
    return x.hex()
