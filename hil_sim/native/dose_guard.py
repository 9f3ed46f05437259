"""The hourly dose limit's bookkeeping compiled: a twin of a fresh :class:`~pressor.runtime.core.dose_guard.DoseGuard`.

Near the library's hourly maximum the guard's taper walks every segment that leaves the hour
within the next ``taper_s`` (up to 6,000 at 0.1 s a tick) on every call: in Python that was most of
a sensitivity sweep's time on the models and levels whose patients run near the maximum (docs/notes/
sensitivity-sweep.md, "Throughput"). ``dose_guard.c`` (beside this file) mirrors
``DoseGuard._hour`` (the charge, the window, the volume leaving within the tick and the taper,
with ``math.fsum``'s exact re-summing) operation for operation; :class:`NativeDoseGuard` is the
same guard with that one method compiled. The rest of :meth:`DoseGuard.limit` (the hard and soft
maxima, the reason, the shortfall) stays the Python's.

:func:`native_dose_guard` returns the guard unchanged where there is no twin (``PRESSOR_NATIVE=off``,
no C compiler, a guard already called, another class). The bedside runtime never uses it.
"""

from __future__ import annotations

import ctypes
import functools
import math
from pathlib import Path

from pressor.plumbing.native_build import NATIVE_ENV, load_twin, native_mode
from pressor.plumbing.native_call import bind
from pressor.runtime.core.dose_guard import DoseGuard

SOURCE = Path(__file__).with_name("dose_guard.c")
#: why the last :func:`native_dose_guard` call gave no twin ("" when it gave one)
last_reason = ""

_d = ctypes.c_double
_i64 = ctypes.c_int64


class _Segment(ctypes.Structure):
    """``seg_t``: one command's (start s, end s, ml)."""

    _fields_ = [("t0", _d), ("t1", _d), ("ml", _d)]


class _State(ctypes.Structure):
    """``guard_t`` of dose_guard.c, field for field."""

    _fields_ = [
        *((name, _d) for name in ("period_s", "taper_s", "hard_max_ml_h", "max_ml_per_hour")),
        ("cap", _i64),
        ("leaving", ctypes.POINTER(_Segment)),
        ("recent", ctypes.POINTER(_Segment)),
        ("leaving_ml", _d),
        ("recent_ml", _d),
        *((name, _i64) for name in ("calls", "lv_head", "lv_len", "rc_head", "rc_len")),
        ("error", ctypes.c_int32),
        ("pad", ctypes.c_int32),
    ]


@functools.cache
def _library() -> ctypes.CDLL | str:
    lib = load_twin(SOURCE, "dose_guard", "dg_state_size", _State)
    if isinstance(lib, str):
        return lib
    lib.dg_hour.restype = _d
    lib.dg_hour.argtypes = [ctypes.c_void_p, _d, _d, _d, ctypes.c_void_p]  # out: used (ml)
    return lib


def ring_capacity(sample_period_s: float) -> int:
    """Segments each ring holds: an hour of calls one period apart, with a margin (the
    simulator calls the guard once a tick; closer calls than that overflow the twin)."""
    return int(math.ceil(3600.0 / sample_period_s * 1.01)) + 64


class NativeDoseGuard(DoseGuard):
    """A fresh :class:`DoseGuard` whose hourly bookkeeping runs compiled (the same contract).

    Parameters
    ----------
    guard
        The fresh guard whose limits, period and horizons the twin takes.
    lib
        The compiled ``dose_guard.c``.
    """

    def __init__(self, guard: DoseGuard, lib: ctypes.CDLL) -> None:
        self._lib = lib
        super().__init__(
            guard.limits,
            guard.period_s,
            guard.taper_s,
            guard.shortfall_after_s,
            guard.shortfall_mmhg,
        )

    def reset(self) -> None:
        """Forget the hour's history."""
        super().reset()
        cap = ring_capacity(self.period_s)
        self._rings = ((_Segment * cap)(), (_Segment * cap)())  # kept alive with the state
        c = self._c = _State()
        c.period_s, c.taper_s = self.period_s, self.taper_s
        c.hard_max_ml_h, c.max_ml_per_hour = self.limits.hard_max_ml_h, self.limits.max_ml_per_hour
        c.cap = cap
        c.leaving = ctypes.cast(self._rings[0], ctypes.POINTER(_Segment))
        c.recent = ctypes.cast(self._rings[1], ctypes.POINTER(_Segment))
        self._used = _d()
        self._used_at = ctypes.addressof(self._used)
        self._hour_c = bind(self._lib.dg_hour, c)

    @property
    def hour_volume_ml(self) -> float:
        """Volume (ml) charged over the last hour (as of the last call)."""
        return max(self._c.leaving_ml + self._c.recent_ml, 0.0)

    def _hour(self, now_s: float) -> tuple[float, float]:
        last = self._last_s
        cap = self._hour_c(
            now_s, math.nan if last is None else last, self._last_ml_h, self._used_at
        )
        if self._c.error:
            what = ("more calls within an hour than its rings hold", "fsum's partials overflowed")
            raise RuntimeError(f"dose guard twin at t={now_s} s: {what[self._c.error - 1]}")
        return self._used.value, cap


def native_dose_guard(guard: DoseGuard | None) -> DoseGuard | None:
    """``guard``'s compiled twin, or ``guard`` itself (:data:`last_reason` says why)."""
    global last_reason
    if guard is None:
        last_reason = "no dose limits"
        return guard
    if native_mode() == "off":
        last_reason = f"{NATIVE_ENV}=off"
        return guard
    if type(guard) is not DoseGuard:
        last_reason = "only the runtime's DoseGuard has a compiled twin"
        return guard
    if guard._calls or guard._last_s is not None:
        last_reason = "the guard has already been called"
        return guard
    lib = _library()
    if isinstance(lib, str):
        last_reason = lib
        return guard
    last_reason = ""
    return NativeDoseGuard(guard, lib)
