"""The shipped LPV controller's double-precision C twin, stepped from Python.

``pressor codegen --target c --c-float`` writes the C twin of a generated module; for the shipped
design it is committed beside the Python module (``runtime/generated/lpv_map_controller.c``) and
tested bit-exact with the module's float step. :func:`native_twin` gives a controller that steps
the compiled C and otherwise is the Python module's ``Controller`` (its class's module constants
stay visible: the supervisor reads the box and rates from them). One step costs one call into the C
(≈ 0.3 µs through :mod:`pressor.plumbing.native_call`, ≈ 1 µs through ctypes) instead of ≈ 7 µs of
Python.

A controller has a twin only when a ``.c`` file sits beside its generated module, was generated
from the same artifact (its header's ``LPVMAP_ARTIFACT_SHA256``) and compiles; otherwise
:func:`native_twin` returns the controller it was given.
"""

from __future__ import annotations

import ctypes
import functools
import re
import sys
from pathlib import Path
from typing import Any

from pressor.plumbing.native_build import NATIVE_ENV, load_twin, native_mode
from pressor.plumbing.native_call import bind

_ARTIFACT = re.compile(r'#define LPVMAP_ARTIFACT_SHA256 "([0-9a-f]{64})"')
#: why the last :func:`native_twin` call gave no twin ("" when it gave one)
last_reason = ""


def _state_struct(n_k: int, nbuf: int) -> type[ctypes.Structure]:
    """The C ``lpvmap_state_t`` (float mode) as a ctypes structure."""
    d, i32, u8 = ctypes.c_double, ctypes.c_int32, ctypes.c_uint8

    class State(ctypes.Structure):
        _fields_ = [
            ("z", d * 4),
            ("buf", (d * nbuf) * n_k),
            ("r", d * 3),
            ("head", i32),
            ("started", i32),
            ("out", d),
            ("saturated", u8),
            ("rho_clamped", u8),
            ("rho_rate_limited", u8),
            ("input_invalid", u8),
            ("m0", d),
            ("y0", d),
            ("ym", d),
            ("rm", d),
            ("uff", d),
            ("pbuf", d * nbuf),
            ("qbuf", d * nbuf),
            ("phead", i32),
            ("anchored", i32),
            ("sf", d),
        ]

    return State


class _Status:
    """The last step's flags, read from the C state (same names as the generated module's)."""

    __slots__ = ("_s",)

    def __init__(self, state: ctypes.Structure) -> None:
        self._s = state

    saturated = property(lambda self: bool(self._s.saturated))
    rho_clamped = property(lambda self: bool(self._s.rho_clamped))
    rho_rate_limited = property(lambda self: bool(self._s.rho_rate_limited))
    input_invalid = property(lambda self: bool(self._s.input_invalid))


@functools.cache
def _twin_class(base: type) -> type | str:
    """A subclass of the generated ``Controller`` ``base`` stepping its compiled C twin, or why not."""
    module = sys.modules.get(base.__module__)
    source = Path(getattr(module, "__file__", "") or "").with_suffix(".c")
    header = source.with_suffix(".h")
    if not source.is_file() or not header.is_file():
        return f"no C twin beside {Path(getattr(module, '__file__', '?')).name}"
    text = header.read_text(encoding="utf-8")
    m = _ARTIFACT.search(text)
    if m is None or m.group(1) != getattr(module, "ARTIFACT_SHA256", None):
        return f"{source.name} was generated from another artifact than its Python module"
    if "Mode: float (double)" not in text:
        return f"{source.name} is not the double-precision twin"
    state_type = _state_struct(int(module.N_K), int(module.DELAY_BUFFER_LEN))
    lib = load_twin(source, "lpvmap", "lpvmap_state_size", state_type)
    if isinstance(lib, str):
        return lib
    lib.lpvmap_step.restype = ctypes.c_double
    lib.lpvmap_step.argtypes = [ctypes.c_void_p] + [ctypes.c_double] * 5
    lib.lpvmap_reset.argtypes = [ctypes.c_void_p]

    class NativeController(base):  # type: ignore[misc, valid-type]
        """The generated controller with its step compiled (see :mod:`pressor.hil_sim.native.controller`)."""

        def __init__(self, fixed_point: bool = False) -> None:
            if fixed_point:
                raise ValueError("the compiled twin is the float data path (fixed_point=False)")
            self.fixed_point = False
            self._c = state_type()
            self._status = _Status(self._c)
            # the C function bound to this state: the per-tick call has no Python frame
            self.step = bind(lib.lpvmap_step, self._c)
            self.reset()

        def reset(self) -> None:
            lib.lpvmap_reset(ctypes.addressof(self._c))

        def state(self) -> tuple[float, ...]:
            return tuple(self._c.z) + tuple(self._c.r)

        def reference(self) -> tuple[float, float, float]:
            s = self._c
            return (s.m0, s.rm, s.uff)

    NativeController.__module__ = base.__module__
    NativeController.__qualname__ = f"{base.__qualname__}(native)"
    return NativeController


def native_twin(controller: Any) -> Any:
    """``controller``'s compiled twin (a fresh, reset controller), or ``controller`` itself.

    A twin exists for a generated LPV module on its float data path whose C twin sits beside it
    (module docstring); PI, Smith, plugins and fixed-point modules come back unchanged.
    :data:`last_reason` says why there was no twin.
    """
    global last_reason
    base = type(controller)
    if native_mode() == "off":
        last_reason = f"{NATIVE_ENV}=off"
        return controller
    if getattr(controller, "fixed_point", True) or not hasattr(base, "_step_float"):
        last_reason = f"{base.__name__} has no compiled twin"
        return controller
    twin = _twin_class(base)
    if isinstance(twin, str):
        last_reason = twin
        return controller
    last_reason = ""
    return twin()
