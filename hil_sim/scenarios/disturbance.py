"""Output disturbances on MAP (mmHg, additive), as functions of simulation time (s).

Kinds (each a small frozen dataclass whose class attribute ``kind`` is the scenario-file name; a
scenario's list is summed, so any combination works):

``hemorrhage``
    Blood loss: MAP falls linearly by ``depth_mmhg`` over ``ramp_s`` from ``start_s`` and stays down.
``bolus``
    Lactated Ringer's bolus: MAP rises linearly by ``amplitude_mmhg`` over ``rise_s`` from
    ``start_s``, then decays exponentially with time constant ``decay_s`` (the fluid redistributes).
``sinusoid``
    Slow physiological swing ``amplitude_mmhg``·sin(2π(t − start)/period + phase) from ``start_s``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar


@dataclass(frozen=True)
class Hemorrhage:
    """Ramp drop of ``depth_mmhg`` over ``ramp_s`` from ``start_s`` (mmHg, s)."""

    kind: ClassVar[str] = "hemorrhage"
    start_s: float
    ramp_s: float
    depth_mmhg: float

    def __call__(self, t_s: float) -> float:
        if t_s <= self.start_s:
            return 0.0
        frac = 1.0 if self.ramp_s <= 0.0 else min((t_s - self.start_s) / self.ramp_s, 1.0)
        return -self.depth_mmhg * frac


@dataclass(frozen=True)
class Bolus:
    """Fluid bolus: rise of ``amplitude_mmhg`` over ``rise_s``, then decay with ``decay_s`` (s)."""

    kind: ClassVar[str] = "bolus"
    start_s: float
    rise_s: float
    amplitude_mmhg: float
    decay_s: float

    def __call__(self, t_s: float) -> float:
        dt = t_s - self.start_s
        if dt <= 0.0:
            return 0.0
        if dt < self.rise_s:
            return self.amplitude_mmhg * dt / self.rise_s
        return self.amplitude_mmhg * math.exp(-(dt - self.rise_s) / self.decay_s)


@dataclass(frozen=True)
class Sinusoid:
    """Slow oscillation of ``amplitude_mmhg`` and ``period_s`` from ``start_s``, phase in degrees."""

    kind: ClassVar[str] = "sinusoid"
    start_s: float
    amplitude_mmhg: float
    period_s: float
    phase_deg: float = 0.0

    def __call__(self, t_s: float) -> float:
        if t_s < self.start_s:
            return 0.0
        arg = 2.0 * math.pi * (t_s - self.start_s) / self.period_s + math.radians(self.phase_deg)
        return self.amplitude_mmhg * math.sin(arg)


Disturbance = Hemorrhage | Bolus | Sinusoid


class DisturbanceSum:
    """The sum of a scenario's disturbances (mmHg) at time t (s); empty → 0."""

    def __init__(self, parts: Sequence[Disturbance] = ()) -> None:
        self.parts = tuple(parts)

    def __call__(self, t_s: float) -> float:
        total = 0.0
        for part in self.parts:
            total += part(t_s)
        return total
