"""The paper patient's step compiled: a twin of a fresh nonlinear :class:`~pressor.hil_sim.patients.patient.Patient`.

``paper_patient.c`` (beside this file) mirrors ``Patient.step`` and its variable delay buffer
operation for operation; :class:`NativePatient` is the same patient (its parameters, coefficients,
reachability; its MAP, K, T, τ read from the C state), stepped by one call into the C
(:mod:`pressor.plumbing.native_call`) instead of ≈ 4 µs of Python. :func:`native_patient` returns
the patient unchanged where there is no twin (``PRESSOR_NATIVE=off``, no C compiler, a frozen
patient, another patient model, one already stepped, an internal step so short that the delay
buffer would not fit). The drug models
(``pkpd``, ``phenylephrine-2c``, ``norepinephrine``) get their twins from
:mod:`pressor.hil_sim.native.drug_patient`; a patient of the
responsiveness sweep (:class:`~pressor.hil_sim.patients.sensitivity.SensitivityScaled`) gets the twin inside
its wrapper.
"""

from __future__ import annotations

import ctypes
import functools
import operator
from pathlib import Path

from pressor.hil_sim.native.drug_patient import drug_twin, has_twin
from pressor.hil_sim.patients import patient as pp
from pressor.hil_sim.patients.patient import Patient, PatientParams
from pressor.hil_sim.patients.sensitivity import SensitivityScaled
from pressor.plumbing.native_build import NATIVE_ENV, load_twin, native_mode
from pressor.plumbing.native_call import bind

SOURCE = Path(__file__).with_name("paper_patient.c")
MAX_RING = 8192
#: why the last :func:`native_patient` call gave no twin ("" when it gave one)
last_reason = ""

_d = ctypes.c_double
_CONSTANTS = (
    "h", "tau_rate_ref", "tau_min", "tau_gain", "tau_max", "T_min", "T_max", "k_decay", "a00",
    "a01", "a10", "a11", "b0", "b1", "b_tau1", "k0", "k1", "b_T",
)  # fmt: skip
_STATE = ("time_s", "delta_map_mmhg", "infused_ml_h_s", "K", "T_s", "tau_s", "x1", "x2", "total")


class _State(ctypes.Structure):
    """``patient_t`` of paper_patient.c, field for field."""

    _fields_ = [
        *((name, _d) for name in _CONSTANTS),
        ("size", ctypes.c_int64),
        *((name, _d) for name in _STATE),
        ("n", ctypes.c_int64),
        ("started", ctypes.c_int32),
        ("error", ctypes.c_int32),
        ("ring", _d * MAX_RING),
    ]


@functools.cache
def _library() -> ctypes.CDLL | str:
    lib = load_twin(SOURCE, "paper_patient", "pp_state_size", _State)
    if isinstance(lib, str):
        return lib
    lib.pp_step.restype = ctypes.c_int32
    lib.pp_step.argtypes = [ctypes.c_void_p, _d]
    return lib


def _state_property(name: str) -> property:
    # attrgetter: read on every tick, and a C-level getter costs no Python frame
    return property(operator.attrgetter(f"_c.{name}"), doc=f"{name} (the C state's)")


class NativePatient(Patient):
    """A fresh nonlinear paper patient whose step runs compiled (same contract as :class:`Patient`).

    Parameters
    ----------
    patient
        The fresh Python patient whose parameters and discretisation the twin takes (not
        stepped by it).
    lib
        The compiled ``paper_patient.c``.
    """

    time_s = _state_property("time_s")
    delta_map_mmhg = _state_property("delta_map_mmhg")
    infused_ml_h_s = _state_property("infused_ml_h_s")
    K = _state_property("K")
    T_s = _state_property("T_s")
    tau_s = _state_property("tau_s")

    def __init__(self, patient: Patient, lib: ctypes.CDLL) -> None:  # no super(): the C holds it
        p: PatientParams = patient.params  # type: ignore[assignment]
        self.params, self.h, self.frozen = p, patient.h, False
        c = self._c = _State()
        c.h, c.tau_rate_ref, c.tau_gain = patient.h, pp.TAU_RATE_REF_ML_H, pp.TAU_GAIN_S
        c.tau_min, c.tau_max, c.T_min, c.T_max = pp.TAU_MIN_S, pp.TAU_MAX_S, pp.T_MIN_S, pp.T_MAX_S
        c.k_decay = patient._k_decay
        (c.a00, c.a01, c.a10, c.a11), (c.b0, c.b1) = patient._ad, patient._bd
        c.b_tau1, c.k0, c.k1, c.b_T = p.b_tau1, p.k0, p.k1, p.b_T
        c.size = patient._buffer.size
        c.time_s, c.delta_map_mmhg, c.infused_ml_h_s = patient.time_s, 0.0, 0.0
        c.K, c.T_s, c.tau_s = patient.K, patient.T_s, patient.tau_s
        self._step = bind(lib.pp_step, c)

    def step(self, rate_ml_h: float) -> None:
        """Advance one internal step with the pump delivering ``rate_ml_h`` (mean over the step)."""
        if self._step(rate_ml_h):
            raise ValueError(f"delay beyond buffer at t={self._c.time_s} s")


def native_patient(patient: object) -> object:
    """``patient``'s compiled twin, or ``patient`` itself (:data:`last_reason` says why)."""
    global last_reason
    if native_mode() == "off":
        last_reason = f"{NATIVE_ENV}=off"
        return patient
    if isinstance(patient, SensitivityScaled):  # the sweep's wrapper: the twin goes inside it
        patient.inner = native_patient(patient.inner)  # type: ignore[assignment]
        return patient
    if has_twin(patient):  # pkpd, phenylephrine-2c, norepinephrine: drug_patients.c
        twin, last_reason = drug_twin(patient)
        return twin
    if type(patient) is not Patient or patient.frozen:
        last_reason = (
            "only the paper's nonlinear patient and the pkpd, phenylephrine-2c and"
            " norepinephrine models have a compiled twin"
        )
        return patient
    if patient._buffer.n or patient._started:
        last_reason = "the patient has already been stepped"
        return patient
    if patient._buffer.size > MAX_RING:
        last_reason = f"the delay buffer needs more than {MAX_RING} steps"
        return patient
    lib = _library()
    if isinstance(lib, str):
        last_reason = lib
        return patient
    last_reason = ""
    return NativePatient(patient, lib)
