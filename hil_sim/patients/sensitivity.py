"""Drug sensitivity scaled by a factor f, for any patient model (a responsiveness sweep).

:class:`SensitivityScaled` wraps a :class:`pressor.hil_sim.patients.patient_model.PatientModel` and feeds it
f × the rate the pump delivered: the patient responds to every ml/h as the unwrapped one responds
to f ml/h. For a Hill/Emax model this divides the potency (EC50) by f and keeps Emax, the way
published drug-responsiveness robustness tests of closed-loop vasopressor systems shift their
simulated patients (Rinehart, Joosten et al. tested theirs on simulated patients at seven
responsiveness levels, 0.1× to 10× nominal). Every state the wrapped model drives with the rate
sees the scaled rate too (the paper model's K(i), T(∫i) and τ filter included).

What the wrapper reports:

- ``K`` = f × the wrapped model's K (mmHg/(ml/h) of *delivered* rate); ``T_s`` and ``tau_s`` are
  the wrapped model's, unchanged;
- ``coefficients()`` = the wrapped model's plus ``sensitivity_factor`` (unit ``1``);
- ``max_delta_map_mmhg(max_rate_ml_h)`` = the wrapped model's at f × ``max_rate_ml_h``;
- MAP, baseline and ΔMAP pass through.

Spec form: ``MODEL@sensitivity=F`` (``MODEL`` a registry name or ``MODULE:CLASS``) is a patient
model like any other for ``--patient-model``, :class:`pressor.hil_sim.world.World` and the trial workers
(:func:`pressor.hil_sim.patients.patient_model.load_patient_model` builds the wrapped class from it);
:func:`with_sensitivity` writes it. A factor of 1 writes no suffix, so a run at f = 1 is the
unwrapped model's, byte for byte. f must lie in :data:`SENSITIVITY_RANGE`.
"""

from __future__ import annotations

import operator
from collections.abc import Mapping
from typing import ClassVar

from pressor.contracts.checks import check_range
from pressor.hil_sim.patients.patient_model import PatientModel, PatientModelError

#: allowed sensitivity factors (dimensionless, inclusive)
SENSITIVITY_RANGE = (0.05, 20.0)
#: what separates a model spec from its factor in the spec form ``MODEL@sensitivity=F``
SPEC_SEPARATOR = "@sensitivity="
#: the coefficient the wrapper adds to the wrapped model's
FACTOR_KEY = "sensitivity_factor"


def check_factor(factor: object, where: str = "sensitivity") -> float:
    """``factor`` as a float after checking it lies in :data:`SENSITIVITY_RANGE`.

    Raises
    ------
    PatientModelError
        A factor that is not a finite number in the range, naming ``where``, the value and the
        range.
    """
    lo, hi = SENSITIVITY_RANGE
    return check_range(
        where,
        factor,
        lo,
        hi,
        error=lambda msg: PatientModelError(
            f"{msg} (the sensitivity factor, dimensionless; 1 = the model as drawn)"
        ),
    )


def split_spec(spec: str) -> tuple[str, float | None]:
    """``(model spec, factor)`` of ``MODEL@sensitivity=F``; ``(spec, None)`` without a suffix.

    Raises
    ------
    PatientModelError
        A suffix whose factor is not a number in :data:`SENSITIVITY_RANGE`.
    """
    base, sep, text = spec.rpartition(SPEC_SEPARATOR)
    if not sep:
        return spec, None
    try:
        value: object = float(text)
    except ValueError:
        value = text
    return base, check_factor(value, f"--patient-model {spec!r}: sensitivity")


def with_sensitivity(spec: str, factor: float) -> str:
    """The patient-model spec of ``spec``'s patients at ``factor`` × their drug sensitivity.

    A factor of 1 returns ``spec`` unchanged (the records keep the unwrapped model's bytes).

    Raises
    ------
    PatientModelError
        A factor outside :data:`SENSITIVITY_RANGE`, or a ``spec`` that already has a factor.
    """
    f = check_factor(factor)
    if f == 1.0:
        return spec
    if split_spec(spec)[1] is not None:
        raise PatientModelError(
            f"--patient-model {spec!r} already scales the sensitivity; give the factor once"
        )
    return f"{spec}{SPEC_SEPARATOR}{f!r}"


class SensitivityScaled:
    """A patient whose drug sensitivity is ``factor`` × that of the wrapped ``inner`` patient.

    Build one per process with :func:`scaled_model` (the class carries the wrapped model and the
    factor, so :meth:`from_seed` keeps the protocol's signature).

    Parameters
    ----------
    inner
        The wrapped patient (any :class:`pressor.hil_sim.patients.patient_model.PatientModel`).
    factor
        The sensitivity factor f (dimensionless, :data:`SENSITIVITY_RANGE`).
    """

    inner_model: ClassVar[type[PatientModel]]
    sensitivity_factor: ClassVar[float]
    coefficient_units: ClassVar[Mapping[str, str]] = {}

    def __init__(self, inner: PatientModel, factor: float) -> None:
        self.inner = inner
        self.factor = check_factor(factor)

    @classmethod
    def from_seed(cls, patient_seed: int, step_s: float) -> SensitivityScaled:
        """The wrapped model's patient of ``patient_seed`` (stepped every ``step_s`` s), scaled."""
        return cls(cls.inner_model.from_seed(patient_seed, step_s), cls.sensitivity_factor)

    # The pass-through members read the wrapped patient through a C-level getter: the world reads
    # them every tick, and a Python property would add a frame each time.
    baseline_mmhg = property(
        operator.attrgetter("inner.baseline_mmhg"), doc="MAP without drug (mmHg), the wrapped's."
    )
    map_mmhg = property(
        operator.attrgetter("inner.map_mmhg"), doc="MAP now (mmHg), the wrapped patient's."
    )
    delta_map_mmhg = property(
        operator.attrgetter("inner.delta_map_mmhg"),
        doc="The drug's MAP change now (mmHg), the wrapped patient's.",
    )

    @property
    def K(self) -> float:
        """f × the wrapped patient's K (mmHg/(ml/h) of delivered rate)."""
        return self.factor * self.inner.K

    T_s = property(
        operator.attrgetter("inner.T_s"), doc="The wrapped patient's lag (s), unchanged."
    )
    tau_s = property(
        operator.attrgetter("inner.tau_s"),
        doc="The wrapped patient's transport delay (s), unchanged.",
    )

    def step(self, rate_ml_h: float) -> None:
        """Advance the wrapped patient one internal step at f × ``rate_ml_h`` (ml/h)."""
        self.inner.step(self.factor * rate_ml_h)

    def coefficients(self) -> dict[str, float]:
        """The wrapped patient's coefficients and ``sensitivity_factor`` (f, dimensionless)."""
        return {**self.inner.coefficients(), FACTOR_KEY: self.factor}

    def max_delta_map_mmhg(self, max_rate_ml_h: float) -> float:
        """The wrapped patient's largest steady-state ΔMAP (mmHg) at f × ``max_rate_ml_h``."""
        return self.inner.max_delta_map_mmhg(self.factor * max_rate_ml_h)


def scaled_model(inner: type[PatientModel], factor: float) -> type[SensitivityScaled]:
    """A :class:`SensitivityScaled` subclass whose patients are ``inner``'s at ``factor``.

    Raises
    ------
    PatientModelError
        A factor outside :data:`SENSITIVITY_RANGE`, or an ``inner`` model that already has a
        ``sensitivity_factor`` coefficient.
    """
    f = check_factor(factor)
    units = dict(inner.coefficient_units)
    if FACTOR_KEY in units:
        raise PatientModelError(
            f"patient model {inner.__name__!r} already has a coefficient {FACTOR_KEY!r}"
        )
    units[FACTOR_KEY] = "1"
    attrs = {"inner_model": inner, "sensitivity_factor": f, "coefficient_units": units}
    return type(f"{inner.__name__}Sensitivity", (SensitivityScaled,), attrs)
