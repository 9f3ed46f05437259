"""Patient models defined outside :mod:`pressor.hil_sim`, loaded by ``--patient-model tests.support.patient_plugin:CLASS``.

:class:`FirstOrderPatient` satisfies :class:`pressor.hil_sim.patients.patient_model.PatientModel`; the others
each lack one thing, for the error messages.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from typing import ClassVar

from pressor.hil_sim.patients.cohort import patient_rng


class FirstOrderPatient:
    """ΔMAP = K·i(t − τ)/(T s + 1) with K, T, τ and the baseline drawn from the seed (stream 0);
    the delay is a whole number of steps, the lag exact for an input held over the step."""

    coefficient_units: ClassVar[Mapping[str, str]] = {
        "K": "mmHg/(ml/h)",
        "T_s": "s",
        "tau_s": "s",
        "baseline_mmhg": "mmHg",
    }

    def __init__(
        self, K: float, T_s: float, tau_s: float, baseline_mmhg: float, step_s: float
    ) -> None:
        self.K, self.T_s, self.baseline_mmhg = K, T_s, baseline_mmhg
        n = max(1, round(tau_s / step_s))
        self.tau_s = n * step_s
        self._line = deque([0.0] * n)
        self._decay = math.exp(-step_s / T_s)
        self.delta_map_mmhg = 0.0

    @classmethod
    def from_seed(cls, patient_seed: int, step_s: float) -> FirstOrderPatient:
        """K in [0.2, 0.8] mmHg/(ml/h), T in [80, 160] s, τ in [10, 30] s, baseline 50-60 mmHg."""
        rng = patient_rng(patient_seed, 0)
        k, t, tau, base = (
            rng.uniform(lo, hi) for lo, hi in ((0.2, 0.8), (80, 160), (10, 30), (50, 60))
        )
        return cls(float(k), float(t), float(tau), float(base), step_s)

    @property
    def map_mmhg(self) -> float:
        """MAP (mmHg)."""
        return self.baseline_mmhg + self.delta_map_mmhg

    def step(self, rate_ml_h: float) -> None:
        """One step at ``rate_ml_h`` (ml/h)."""
        self._line.append(rate_ml_h)
        u = self._line.popleft()
        d = self._decay
        self.delta_map_mmhg = d * self.delta_map_mmhg + (1.0 - d) * self.K * u

    def coefficients(self) -> dict[str, float]:
        """K, T, τ, baseline."""
        return {
            "K": self.K,
            "T_s": self.T_s,
            "tau_s": self.tau_s,
            "baseline_mmhg": self.baseline_mmhg,
        }

    def max_delta_map_mmhg(self, max_rate_ml_h: float) -> float:
        """K·max (mmHg)."""
        return self.K * max_rate_ml_h


class NoStep(FirstOrderPatient):
    """A model whose ``step`` is not a method."""

    step = None  # type: ignore[assignment]


class NoDelay(FirstOrderPatient):
    """A model whose patients have no numeric ``tau_s``."""

    @classmethod
    def from_seed(cls, patient_seed: int, step_s: float) -> NoDelay:
        """The first-order patient, its delay then set to None."""
        patient = super().from_seed(patient_seed, step_s)
        patient.tau_s = None  # type: ignore[assignment]
        return patient  # type: ignore[return-value]
