"""A compiled twin's step function bound to its state: a typed CPython caller where one builds.

A ctypes call converts its arguments through the function's ``argtypes`` and costs about 1 µs; a
simulated tick calls its twins (patient, controller, dose guard) several times, so on a cohort that
is a tenth of the time. ``native_call.c`` is a small extension module of callers named by the C
signature they call (``d_pddddd``: a double from a state pointer and five doubles); :func:`bind`
picks the caller from the ctypes declaration the twin's wrapper already makes, so the two cannot
disagree. The caller passes each double as Python holds it to the same compiled function, so the
results are the same bits as through ctypes (``tests/plumbing/test_native_call.py``).

Where the extension does not build (no ``Python.h``: the interpreter's development headers are
not installed; ``PRESSOR_NATIVE=off``; no compiler) or the signature is not one of
:data:`SIGNATURES`, :func:`bind` returns the ctypes call, as before; :data:`reason` says why.
"""

from __future__ import annotations

import ctypes
import functools
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

from pressor.plumbing.native_build import load_extension

SOURCE = Path(__file__).with_name("native_call.c")
MODULE = "_pressor_native_call"

_p, _d, _i32, _i64 = ctypes.c_void_p, ctypes.c_double, ctypes.c_int32, ctypes.c_int64
#: (restype, argtypes) of a ctypes function -> the caller in ``native_call.c`` that calls it
SIGNATURES: dict[tuple[Any, tuple[Any, ...]], str] = {
    (_i32, (_p, _d)): "i_pd",
    (None, (_p, _d)): "v_pd",
    (_d, (_p, _d, _d, _d, _d, _d)): "d_pddddd",
    (_d, (_p, _d, _d, _d, _p)): "d_pdddp",
    (_i32, (_p, _d, _i64, _d)): "i_pdqd",
}


@functools.cache
def callers() -> ModuleType | str:
    """The compiled callers (built once per process), or why there are none."""
    return load_extension(SOURCE, MODULE)


def reason() -> str:
    """Why :func:`bind` falls back to ctypes ("" when the callers are there)."""
    ext = callers()
    return ext if isinstance(ext, str) else ""


def bind(fn: Any, state: ctypes.Structure, fast: bool = True) -> Callable[..., Any]:
    """``fn`` (a ctypes function whose first argument is ``state``'s address, with its ``restype``
    and ``argtypes`` declared) bound to ``state``: called with the remaining arguments.

    Pointer arguments after the state are passed as Python ints (addresses). ``fast=False`` gives
    the ctypes call (the reference the compiled callers are tested against). The bound function
    holds no reference to ``state``: the caller keeps it alive.
    """
    address = ctypes.addressof(state)
    ext = callers() if fast else None
    name = SIGNATURES.get((fn.restype, tuple(fn.argtypes or ())))
    if not isinstance(ext, ModuleType) or name is None:
        return functools.partial(fn, address)
    return functools.partial(getattr(ext, name), ctypes.cast(fn, ctypes.c_void_p).value, address)
