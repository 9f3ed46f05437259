"""The drug patient models' steps compiled: twins of fresh ``pkpd``, ``phenylephrine-2c`` and
``norepinephrine`` patients.

``drug_patients.c`` (beside this file) mirrors :meth:`Phenylephrine2C.step
<pressor.hil_sim.patients.phenylephrine.Phenylephrine2C.step>`, :meth:`Norepinephrine1C.step
<pressor.hil_sim.patients.norepinephrine.Norepinephrine1C.step>` (with
:class:`~pressor.hil_sim.patients.drug_patient.DrugPatient`'s delay line and counter-regulation) and
:meth:`IndependentPatient.step <pressor.hil_sim.patients.pkpd.IndependentPatient.step>` operation
for operation, and leaves after each step the MAP, ΔMAP and K the world reads every tick, evaluated
as the Python properties evaluate them. Each twin class here is the Python model (its parameters,
coefficients, steady states and reachability are the inherited methods) with its state read from
the C and its step one call into the C (:mod:`pressor.plumbing.native_call`).
:func:`pressor.hil_sim.native.patient.native_patient` dispatches here; :func:`drug_twin` gives the
twin or the reason there is none.
"""

from __future__ import annotations

import ctypes
import functools
import operator
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pressor.hil_sim.patients.norepinephrine import Norepinephrine1C
from pressor.hil_sim.patients.phenylephrine import Phenylephrine2C
from pressor.hil_sim.patients.pkpd import PkpdPatient
from pressor.plumbing.native_build import load_twin
from pressor.plumbing.native_call import bind

SOURCE = Path(__file__).with_name("drug_patients.c")
MAX_RING = 8192

_d = ctypes.c_double
_i64 = ctypes.c_int64


class _Delay(ctypes.Structure):
    """``delay_t``: VariableDelayBuffer."""

    _fields_ = [
        ("h", _d),
        ("total", _d),
        ("size", _i64),
        ("n", _i64),
        ("error", ctypes.c_int32),
        ("pad", ctypes.c_int32),
        ("ring", _d * MAX_RING),
    ]


class _Drug(ctypes.Structure):
    """``drug_t``: DrugPatient's counter-regulation and what the world reads."""

    _fields_ = [
        (name, _d)
        for name in (
            "q",
            "g",
            "counter_tau_s",
            "baseline_mmhg",
            "delay_s",
            "time_s",
            "counter_mmhg",
            "effect_now",
            "delta_map_mmhg",
            "map_mmhg",
            "K",
        )  # fmt: skip
    ]


class _Phenylephrine(ctypes.Structure):
    """``phenylephrine_t``."""

    _fields_ = [
        ("conc_ug_ml", _d),
        ("a", _d * 9),
        ("b", _d * 3),
        *((name, _d) for name in ("emax_mmhg", "ec50_ng_ml", "fast_dc_ng_ml")),
        *((name, _d) for name in ("a1_ug", "a2_ug", "ce_ng_ml")),
        ("d", _Drug),
        ("buf", _Delay),
    ]


class _Norepinephrine(ctypes.Structure):
    """``norepinephrine_t``."""

    _fields_ = [
        ("conc_ug_ml", _d),
        ("a", _d * 4),
        ("b", _d * 2),
        *(
            (name, _d)
            for name in (
                "endogenous_ug_min",
                "emax_mmhg",
                "ec50_ng_ml",
                "hill",
                "h_endo",
                "dc_ng_ml",
                "plasma_ng_ml",
                "ce_ng_ml",
                "hill_now",
            )  # fmt: skip
        ),
        ("d", _Drug),
        ("buf", _Delay),
    ]


_PKPD_CONSTANTS = (
    "ts_s", "conc_ug_ml", "baseline_mmhg", "cl_l_min", "v1_l", "q_l_min", "v2_l", "effect_lag_s",
    "emax_mmhg", "ec50_ng_ml", "hill", "tolerance_tau_s", "tolerance_gain", "fast_dc_ng_ml",
)  # fmt: skip
_PKPD_STATE = (
    "a1_ug", "a2_ug", "ce_ng_ml", "tol_ng_ml", "t_s", "delta_map_mmhg", "map_mmhg", "K",
)  # fmt: skip


class _Pkpd(ctypes.Structure):
    """``pkpd_t``."""

    _fields_ = [
        *((name, _d) for name in (*_PKPD_CONSTANTS, *_PKPD_STATE)),
        ("pipe_len", _i64),
        ("pipe_head", _i64),
        ("pipe", _d * MAX_RING),
    ]


@functools.cache
def _library() -> ctypes.CDLL | str:
    lib = load_twin(SOURCE, "drug_patients", "dp_phenylephrine_size", _Phenylephrine)
    if isinstance(lib, str):
        return lib
    for name, state in (("norepinephrine", _Norepinephrine), ("pkpd", _Pkpd)):
        size = getattr(lib, f"dp_{name}_size")
        size.restype = ctypes.c_uint32
        if size() != ctypes.sizeof(state):
            return f"{SOURCE.name}: {name} state layout differs from the one this wrapper knows"
    for name in ("phenylephrine", "norepinephrine"):
        fn = getattr(lib, f"dp_{name}_step")
        fn.restype, fn.argtypes = ctypes.c_int32, [ctypes.c_void_p, _d]
    lib.dp_pkpd_step.restype, lib.dp_pkpd_step.argtypes = None, [ctypes.c_void_p, _d]
    return lib


def _c(path: str, doc: str) -> property:
    # attrgetter: read on every tick, and a C-level getter costs no Python frame
    return property(operator.attrgetter(f"_c.{path}"), doc=doc)


def _adopt(twin: Any, patient: Any, state: tuple[str, ...]) -> None:
    """The twin takes the fresh patient's attributes but its state (which the C holds)."""
    twin.__dict__.update(
        {k: v for k, v in patient.__dict__.items() if k not in state and k != "_buffer"}
    )


def _fill_delay(buf: _Delay, patient: Any) -> None:
    buf.h, buf.total, buf.size, buf.n = patient._buffer.h, 0.0, patient._buffer.size, 0


def _fill_drug(d: _Drug, patient: Any) -> None:
    d.q, d.g = patient._counter_decay, patient.params.counter_gain
    d.counter_tau_s, d.baseline_mmhg = patient._counter_tau_s, patient.params.baseline_mmhg
    d.delay_s, d.time_s, d.counter_mmhg = patient.params.delay_s, 0.0, 0.0
    d.effect_now = patient._effect_before_step()
    d.delta_map_mmhg, d.map_mmhg, d.K = patient.delta_map_mmhg, patient.map_mmhg, patient.K


def _fill_drug_patient(c: Any, patient: Any) -> None:
    """What every DrugPatient twin's struct takes alike: the syringe, the kinetics' discrete
    matrices, the drug state and the delay line."""
    c.conc_ug_ml = patient.conc_ug_ml
    c.a[:] = [v for row in patient._ad for v in row]
    c.b[:] = list(patient._bd)
    _fill_drug(c.d, patient)
    _fill_delay(c.buf, patient)


def _checked(step: Callable[[float], int], c: Any) -> Callable[[float], None]:
    def run(rate_ml_h: float) -> None:
        if step(rate_ml_h):
            raise ValueError(f"delay beyond buffer at t={c.d.time_s} s")

    return run


_DRUG_STATE = ("time_s", "counter_mmhg", "_effect_now")


class NativePhenylephrine2C(Phenylephrine2C):
    """A fresh ``phenylephrine-2c`` patient whose step runs compiled (same contract)."""

    time_s = _c("d.time_s", "Time (s).")
    counter_mmhg = _c("d.counter_mmhg", "F (mmHg).")
    delta_map_mmhg = _c("d.delta_map_mmhg", "The drug's MAP change now (mmHg): E − F.")
    map_mmhg = _c("d.map_mmhg", "MAP now (mmHg), without the scenario's disturbances.")
    K = _c("d.K", "Apparent sensitivity now (mmHg/(ml/h)).")
    _effect_now = _c("d.effect_now", "E (mmHg) at the effect-site level the last step left.")
    a1_ug = _c("a1_ug", "Central amount (µg).")
    a2_ug = _c("a2_ug", "Peripheral amount (µg).")
    ce_ng_ml = _c("ce_ng_ml", "Effect-site level (ng/ml).")
    T_s = property(operator.attrgetter("_t_app_s"), doc="Apparent lag (s).")
    tau_s = property(operator.attrgetter("_tau_s"), doc="Transport delay d (s).")

    def __init__(self, patient: Phenylephrine2C, lib: ctypes.CDLL) -> None:  # no super()
        _adopt(self, patient, (*_DRUG_STATE, "a1_ug", "a2_ug", "ce_ng_ml"))
        self._tau_s = patient.tau_s
        c = self._c = _Phenylephrine()
        _fill_drug_patient(c, patient)
        c.emax_mmhg, c.ec50_ng_ml = patient.params.emax_mmhg, patient.params.ec50_ng_ml
        c.fast_dc_ng_ml = patient._fast_dc_ng_ml
        c.a1_ug, c.a2_ug, c.ce_ng_ml = patient.a1_ug, patient.a2_ug, patient.ce_ng_ml
        self.step = _checked(bind(lib.dp_phenylephrine_step, c), c)


class NativeNorepinephrine1C(Norepinephrine1C):
    """A fresh ``norepinephrine`` patient whose step runs compiled (same contract)."""

    time_s = _c("d.time_s", "Time (s).")
    counter_mmhg = _c("d.counter_mmhg", "F (mmHg).")
    delta_map_mmhg = _c("d.delta_map_mmhg", "The drug's MAP change now (mmHg): E − F.")
    map_mmhg = _c("d.map_mmhg", "MAP now (mmHg), without the scenario's disturbances.")
    K = _c("d.K", "Apparent sensitivity now (mmHg/(ml/h)).")
    _effect_now = _c("d.effect_now", "E (mmHg) at the effect-site level the last step left.")
    plasma_ng_ml = _c("plasma_ng_ml", "Plasma level (ng/ml).")
    ce_ng_ml = _c("ce_ng_ml", "Effect-site level (ng/ml).")
    _hill_now = _c("hill_now", "H (mmHg) at the effect-site level the last step left.")
    T_s = property(operator.attrgetter("_t_app_s"), doc="Apparent lag (s).")
    tau_s = property(operator.attrgetter("_tau_s"), doc="Transport delay d (s).")

    def __init__(self, patient: Norepinephrine1C, lib: ctypes.CDLL) -> None:  # no super()
        state = (*_DRUG_STATE, "plasma_ng_ml", "ce_ng_ml", "_hill_now")
        _adopt(self, patient, state)
        self._tau_s = patient.tau_s
        c = self._c = _Norepinephrine()
        _fill_drug_patient(c, patient)
        c.endogenous_ug_min = patient.params.endogenous_ug_min
        c.emax_mmhg, c.ec50_ng_ml = patient._emax_mmhg, patient._ec50_ng_ml
        c.hill, c.h_endo, c.dc_ng_ml = patient._hill, patient._h_endo, patient._dc_ng_ml
        c.plasma_ng_ml, c.ce_ng_ml = patient.plasma_ng_ml, patient.ce_ng_ml
        c.hill_now = patient.hill_mmhg(patient.ce_ng_ml)  # what K uses before the first step
        self.step = _checked(bind(lib.dp_norepinephrine_step, c), c)


class NativePkpdPatient(PkpdPatient):
    """A fresh ``pkpd`` patient whose step runs compiled (same contract)."""

    a1_ug = _c("a1_ug", "Central amount (µg).")
    a2_ug = _c("a2_ug", "Peripheral amount (µg).")
    ce_ng_ml = _c("ce_ng_ml", "Effect-site level (ng/ml).")
    tol_ng_ml = _c("tol_ng_ml", "Tolerance state (ng/ml).")
    t_s = _c("t_s", "Time (s).")
    delta_map_mmhg = _c("delta_map_mmhg", "The drug's MAP rise now (mmHg).")
    map_mmhg = _c("map_mmhg", "True MAP now (mmHg).")
    K = _c("K", "Apparent sensitivity now (mmHg/(ml/h)).")
    T_s = property(operator.attrgetter("_t_app_s"), doc="Apparent lag (s).")
    tau_s = property(operator.attrgetter("_tau_s"), doc="Transport delay (s).")

    def __init__(self, patient: PkpdPatient, lib: ctypes.CDLL) -> None:  # no super()
        _adopt(self, patient, (*_PKPD_STATE, "pipe"))
        p = patient.p
        c = self._c = _Pkpd()
        c.ts_s, c.conc_ug_ml = patient.ts_s, patient.conc_ug_ml
        for name in _PKPD_CONSTANTS[2:-1]:
            setattr(c, name, getattr(p, name))
        c.fast_dc_ng_ml = patient._fast_dc_ng_ml
        for name in _PKPD_STATE:
            setattr(c, name, getattr(patient, name))
        c.pipe_len, c.pipe_head = len(patient.pipe), 0
        self.step = bind(lib.dp_pkpd_step, c)


_TWINS: dict[type, type] = {
    Phenylephrine2C: NativePhenylephrine2C,
    Norepinephrine1C: NativeNorepinephrine1C,
    PkpdPatient: NativePkpdPatient,
}


def has_twin(patient: object) -> bool:
    """Whether ``patient``'s class is one of the drug models with a compiled twin."""
    return type(patient) in _TWINS


def drug_twin(patient: Any) -> tuple[Any, str]:
    """``(twin, "")`` of a fresh drug patient (:func:`has_twin`), or ``(patient, why not)``."""
    if isinstance(patient, PkpdPatient):
        fresh = patient.t_s == 0.0 and patient.a1_ug == 0.0 and not any(patient.pipe)
        size = len(patient.pipe)
    else:
        fresh, size = patient._buffer.n == 0, patient._buffer.size
    if not fresh:
        return patient, "the patient has already been stepped"
    if size > MAX_RING:
        return patient, f"the delay line needs more than {MAX_RING} steps"
    lib = _library()
    if isinstance(lib, str):
        return patient, lib
    return _TWINS[type(patient)](patient, lib), ""
