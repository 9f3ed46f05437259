"""What the published drug models (``norepinephrine``, ``phenylephrine-2c``) share.

Both draw their constants from ranges (:func:`draw_constants`) and both give MAP as a baseline plus
a drug effect E less a counter-regulation F that takes back the fraction g of a sustained effect
with the time constant τ_cr, after the line delay d::

    dF/dt = (g · E − F) / τ_cr,    MAP = baseline + E − F

:class:`DrugPatient` holds that part: the delay line the pump's rate goes through, F's exact update
for an E moving linearly over the internal step, and the properties that follow from E and F. A
model adds its kinetics, its E (:meth:`DrugPatient.effect_mmhg`), its apparent K and T and its
steady state.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict
from typing import Any, ClassVar

from pressor.hil_sim.patients.cohort import patient_rng
from pressor.hil_sim.patients.patient import VariableDelayBuffer

__all__ = ["DrugPatient", "draw_constants"]


def draw_constants(
    patient_seed: int, ranges: Mapping[str, tuple[float, float]], log_uniform: frozenset[str]
) -> dict[str, float]:
    """One patient's constants: stream 0 of :func:`pressor.hil_sim.patients.cohort.patient_rng` draws the
    ``ranges`` in their order, uniformly, the names in ``log_uniform`` log-uniformly."""
    rng = patient_rng(patient_seed, 0)
    values = {}
    for name, (lo, hi) in ranges.items():
        if name in log_uniform:
            values[name] = float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
        else:
            values[name] = float(rng.uniform(lo, hi))
    return values


class DrugPatient:
    """The delay line, the counter-regulation and E − F of a drug model (module docstring).

    Parameters
    ----------
    params
        The patient's constants: a dataclass with ``baseline_mmhg``, ``delay_s`` (s) and
        ``counter_gain`` (g, in [0, 1)).
    step_s
        Internal step (s), in (0, 10] (the discretisations are exact, the step only sets the grid).
    conc_ug_ml
        The syringe concentration (µg/ml) the model's ml/h count.
    counter_tau_s
        τ_cr (s), > 0.

    Attributes
    ----------
    time_s, counter_mmhg
        Time (s), F (mmHg); a model adds its levels (``ce_ng_ml`` the effect site's, ng/ml).
    """

    #: the model's name, as its messages give it
    model_name: ClassVar[str]
    ce_ng_ml: float

    def __init__(self, params: Any, step_s: float, conc_ug_ml: float, counter_tau_s: float) -> None:
        if not 0.0 < step_s <= 10.0:
            raise ValueError(f"{self.model_name} step_s={step_s!r} outside (0, 10] s")
        self.params = params
        self.h = float(step_s)
        self.conc_ug_ml = conc_ug_ml
        self._buffer = VariableDelayBuffer(self.h, params.delay_s)
        self._counter_tau_s = counter_tau_s
        self._counter_decay = math.exp(-self.h / counter_tau_s)
        self.time_s = 0.0
        self.counter_mmhg = 0.0
        #: E (mmHg) at the effect-site level the last step left, ``None`` before the first step:
        #: the next step starts from it and the world reads MAP and K from it every tick, so it is
        #: kept instead of evaluated again (the same arithmetic on the same level: the same bits)
        self._effect_now: float | None = None

    def effect_mmhg(self, ce_ng_ml: float) -> float:
        """Direct drug effect E (mmHg) at the effect-site level ``ce_ng_ml`` (ng/ml)."""
        raise NotImplementedError

    def _delayed_rate_ml_h(self, rate_ml_h: float) -> float:
        """Push the pump's mean rate of this step (ml/h); the mean rate d s earlier (ml/h)."""
        self._buffer.push(rate_ml_h)
        d = self.params.delay_s
        return self._buffer.delayed_mean(d, d)

    def _regulate(self, e0: float, e1: float) -> None:
        """Advance F over the step in which E moved linearly from ``e0`` to ``e1`` (mmHg), exactly,
        and the clock by one step."""
        q, g = self._counter_decay, self.params.counter_gain
        ramp = 1.0 - self._counter_tau_s * (1.0 - q) / self.h  # weight of the effect's change
        self.counter_mmhg = q * self.counter_mmhg + g * (e0 * (1.0 - q) + (e1 - e0) * ramp)
        self.time_s = self._buffer.n * self.h
        self._effect_now = e1

    def _effect_before_step(self) -> float:
        """E (mmHg) at the current effect-site level, before this step moves it."""
        e = self._effect_now
        return self.effect_mmhg(self.ce_ng_ml) if e is None else e

    @property
    def baseline_mmhg(self) -> float:
        """MAP without drug (mmHg)."""
        return self.params.baseline_mmhg

    @property
    def delta_map_mmhg(self) -> float:
        """The drug's MAP change now (mmHg): E − F."""
        return self._effect_before_step() - self.counter_mmhg

    @property
    def map_mmhg(self) -> float:
        """MAP now (mmHg), without the scenario's disturbances."""
        return self.params.baseline_mmhg + self.delta_map_mmhg

    @property
    def tau_s(self) -> float:
        """Transport delay d (s)."""
        return self.params.delay_s

    def coefficients(self) -> dict[str, float]:
        """The patient's constants, JSON-ready."""
        return {k: float(v) for k, v in asdict(self.params).items()}

    def steady_state_delta_mmhg(self, rate_ml_h: float) -> float:
        """ΔMAP (mmHg) after an endless infusion at ``rate_ml_h`` (ml/h): (1 − g)·E(Css)."""
        raise NotImplementedError

    def max_delta_map_mmhg(self, max_rate_ml_h: float) -> float:
        """Largest steady-state ΔMAP (mmHg) over [0, ``max_rate_ml_h``] ml/h (it rises with R)."""
        return self.steady_state_delta_mmhg(max_rate_ml_h)
