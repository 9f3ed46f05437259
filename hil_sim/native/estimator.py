"""The online estimator's per-tick arithmetic compiled: a twin of a fresh ``DelayBankEstimator``.

``delay_bank.c`` (beside this file) mirrors :mod:`pressor.runtime.estimation` (the sample gate, the window
noise, the delay bank's filters, the selection and the restarts) operation for operation; this
module fills its settings from a freshly built :class:`~pressor.runtime.estimation.estimator.
DelayBankEstimator` and builds the same :class:`~pressor.runtime.core.estimate.Estimate` reports from what
the C leaves in its state. One tick costs one call into the C (:mod:`pressor.plumbing.native_call`)
instead of ≈ 6 µs of Python on average. :func:`native_estimator` returns the estimator unchanged
where there is no compiled twin (``PRESSOR_NATIVE=off``, no C compiler, a customised gate or
estimator class, one already used).
"""

from __future__ import annotations

import ctypes
import functools
import math
from pathlib import Path

from pressor.plumbing.native_build import NATIVE_ENV, load_twin, native_mode
from pressor.plumbing.native_call import bind
from pressor.runtime.core.estimate import Estimate
from pressor.runtime.core.scheduling import ScheduleSource
from pressor.runtime.estimation.estimator import DelayBankEstimator
from pressor.runtime.estimation.gate import SampleGate
from pressor.runtime.estimation.sources import EstimatedSchedule

SOURCE = Path(__file__).with_name("delay_bank.c")
MAX_MODELS = 64
MAX_RING = 128
#: the C's verdict codes -> the Python estimator's reasons
_REASONS = ("ok", "diverged", "K implausible", "T implausible", "learning")
#: why the last :func:`native_estimator` call gave no twin ("" when it gave one)
last_reason = ""

_d, _i32, _i64 = ctypes.c_double, ctypes.c_int32, ctypes.c_int64


class _Bank(ctypes.Structure):
    """``bank_t`` of delay_bank.c, field for field."""

    _fields_ = [
        *((name, _i32) for name in ("n", "n_win", "per_tick", "ring_len", "min_age", "flat_ticks")),
        *(
            (name, _d)
            for name in (
                "window_s",
                "prior_K",
                "prior_T_s",
                "prior_rel_std",
                "baseline_std",
                "q_a2",
                "q_b2",
                "q_c2",
                "jump2",
                "forget",
                "a_lo",
                "a_hi",
                "reseed",
                "learn",
                "tau_offset",
                "drift",
                "K_lo",
                "K_hi",
                "T_lo",
                "T_hi",
                "g_lo",
                "g_hi",
                "g_jump",
                "g_slew_per_tick",
                "nz_floor",
                "nz_gain",
            )
        ),  # fmt: skip
        ("delay_windows", _i32 * MAX_MODELS),
        ("delays_s", _d * MAX_MODELS),
        ("pen", _d * MAX_MODELS),
        ("g_last", _d),
        ("g_prev", _d),
        ("g_since", _i64),
        ("g_run", _i64),
        ("g_rejected", _i64),
        ("g_reason", _i32),
        *((name, _d) for name in ("nz_y1", "nz_y2", "nz_y3", "nz_var")),
        *((name, _i32) for name in ("phase", "ny", "nu", "next", "learned", "rejection")),
        ("j", _i64),
        ("updates", _i64),
        *((name, _d) for name in ("ysum", "usum", "y_dev", "dT", "y_ref")),
        ("uring", _d * MAX_RING),
        ("order", _i32 * MAX_MODELS),
        ("w", _d * MAX_MODELS),
        ("theta", (_d * 3) * MAX_MODELS),
        ("P", (_d * 6) * MAX_MODELS),
        ("sim", (_d * 4) * MAX_MODELS),
        ("nll", _d * MAX_MODELS),
        ("age", _i64 * MAX_MODELS),
        ("out_kind", _i32),
        ("out_healthy", _i32),
        *(
            (name, _d)
            for name in (
                "out_K",
                "out_T",
                "out_tau",
                "out_K_std",
                "out_T_std",
                "out_tau_lo",
                "out_tau_hi",
                "out_confidence",
            )
        ),  # fmt: skip
    ]


@functools.cache
def _library() -> ctypes.CDLL | str:
    lib = load_twin(SOURCE, "delay_bank", "db_state_size", _Bank)
    if isinstance(lib, str):
        return lib
    lib.db_init.argtypes = [ctypes.c_void_p]
    lib.db_update.restype = ctypes.c_int32
    lib.db_update.argtypes = [ctypes.c_void_p, _d, _i64, _d]
    return lib


def _fill(state: _Bank, est: DelayBankEstimator) -> None:
    """The C settings from the Python estimator's (its private fields: this is its twin)."""
    bank = est._bank
    st = bank[0].settings
    gate, noise = est.gate, est._noise
    state.n, state.n_win, state.per_tick = len(bank), est._n_win, est._per_tick
    state.ring_len, state.min_age, state.flat_ticks = (
        len(est._uring),
        est._min_age,
        gate._flat_ticks,
    )
    for name in (
        "window_s", "prior_K", "prior_T_s", "prior_rel_std", "q_a2", "q_b2", "q_c2", "jump2",
        "forget", "a_lo", "a_hi",
    ):  # fmt: skip
        setattr(state, name, getattr(st, name))
    state.baseline_std = st.baseline_std_mmhg
    state.reseed, state.learn, state.tau_offset = est._reseed, est._learn, est._tau_offset
    state.drift = est._drift
    (state.K_lo, state.K_hi), (state.T_lo, state.T_hi) = est._K_pl, est._T_pl
    state.g_lo, state.g_hi, state.g_jump = gate._lo, gate._hi, gate._jump
    state.g_slew_per_tick = gate._slew_per_tick
    state.nz_floor, state.nz_gain = noise._floor, noise._gain
    for m, model in enumerate(bank):
        state.delay_windows[m] = model.delay_windows
        state.delays_s[m] = est.delays_s[m]
        state.pen[m] = est._pen[m]
    state.g_last = state.g_prev = math.nan
    state.nz_y1 = state.nz_y2 = state.nz_y3 = math.nan
    state.nz_var = noise.variance
    state.j = -1
    state.y_dev = state.y_ref = math.nan
    state.next = len(bank)
    for k in range(len(est._uring)):
        state.uring[k] = math.nan


class NativeDelayBankEstimator:
    """The compiled twin of a fresh :class:`DelayBankEstimator` (same :meth:`update` contract).

    Parameters
    ----------
    estimator
        The Python estimator whose settings and priors the twin takes (and whose prior reports
        it returns); it must not have been updated yet, and is not updated by the twin.
    lib
        The compiled ``delay_bank.c``.
    """

    def __init__(self, estimator: DelayBankEstimator, lib: ctypes.CDLL) -> None:
        self._py = estimator
        self.box, self.prior, self.delays_s = estimator.box, estimator.prior, estimator.delays_s
        self.window_s = estimator.window_s
        self._c = _Bank()
        _fill(self._c, estimator)
        lib.db_init(ctypes.addressof(self._c))
        self._update = bind(lib.db_update, self._c)
        self.estimate = estimator.estimate

    @property
    def updates(self) -> int:
        """Filter updates done (all models)."""
        return int(self._c.updates)

    @property
    def windows_closed(self) -> int:
        """How many windows have closed."""
        return int(self._c.j) + 1

    def update(self, map_mmhg: float, quality: int, delivered_ml_h: float) -> Estimate:
        """Take one tick's MAP (mmHg), monitor quality bits and delivered rate (ml/h)."""
        if self._update(map_mmhg, quality, delivered_ml_h):
            s = self._c
            kind = s.out_kind
            if kind:
                self.estimate = self._py._fallback(_REASONS[kind], bool(s.out_healthy))
            else:
                K, T, tau = s.out_K, s.out_T, s.out_tau
                self.estimate = Estimate(
                    K, T, tau, s.out_K_std, s.out_T_std, s.out_tau_lo, s.out_tau_hi,
                    s.out_confidence, True, False, "ok", self._py._inside(K, T, tau),
                )  # fmt: skip
        return self.estimate


def native_estimator(
    estimator: DelayBankEstimator,
) -> DelayBankEstimator | NativeDelayBankEstimator:
    """``estimator``'s compiled twin, or ``estimator`` itself (:data:`last_reason` says why)."""
    global last_reason
    if native_mode() == "off":
        last_reason = f"{NATIVE_ENV}=off"
        return estimator
    if type(estimator) is not DelayBankEstimator or type(estimator.gate) is not SampleGate:
        last_reason = "a customised estimator or gate has no compiled twin"
        return estimator
    if estimator.windows_closed or estimator._phase:
        last_reason = "the estimator has already been updated"
        return estimator
    if len(estimator._bank) > MAX_MODELS or len(estimator._uring) > MAX_RING:
        last_reason = f"more than {MAX_MODELS} delays or {MAX_RING} windows of delay"
        return estimator
    lib = _library()
    if isinstance(lib, str):
        last_reason = lib
        return estimator
    last_reason = ""
    return NativeDelayBankEstimator(estimator, lib)


def native_schedule(schedule: ScheduleSource) -> ScheduleSource:
    """``schedule`` with its estimator's compiled twin where it is the ``estimated`` source (fresh,
    not yet updated); any other source comes back as it is."""
    if type(schedule) is EstimatedSchedule:
        schedule.estimator = native_estimator(schedule.estimator)  # type: ignore[assignment]
    return schedule
