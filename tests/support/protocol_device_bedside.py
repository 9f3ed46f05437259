"""The bedside the protocol device plays: its patient, syringe pump and monitor.

Part of the independent device of ``tests/support/protocol_device.py`` (written from docs/PROTOCOL.md
alone) and under the same rule: it imports the standard library only, nothing of the project (a
test scans its imports). :class:`Patient` is the device's own first order plus transport delay;
:class:`PatientModel` is what a caller's patient must offer to replace it.
"""

from __future__ import annotations

import math
import random
from collections import deque
from types import ModuleType
from typing import Protocol


class PatientModel(Protocol):
    """What the device needs of a patient: the true MAP now and one sample period's advance."""

    @property
    def map_mmhg(self) -> float:
        """True MAP now (mmHg)."""
        ...

    def step(self, rate_ml_h: float) -> None:
        """Advance one sample period with the pump delivering ``rate_ml_h`` (ml/h)."""
        ...


class Patient:
    """First order plus transport delay around a baseline, exact ZOH at the sample period.

    MAP(s) = baseline + K e^{-tau s} / (T s + 1) * rate, K in mmHg/(ml/h), T and tau in s.
    """

    def __init__(self, K: float, T_s: float, tau_s: float, baseline_mmhg: float, Ts_s: float):
        self.K, self.T_s, self.tau_s = K, T_s, tau_s
        self.baseline_mmhg = baseline_mmhg
        self.a = math.exp(-Ts_s / T_s)
        self.pipe = deque([0.0] * max(1, round(tau_s / Ts_s)))
        self.rise_mmhg = 0.0

    @property
    def map_mmhg(self) -> float:
        """True MAP now (mmHg)."""
        return self.baseline_mmhg + self.rise_mmhg

    def step(self, rate_ml_h: float) -> None:
        """Advance one sample period with the pump delivering ``rate_ml_h`` (ml/h)."""
        self.pipe.append(rate_ml_h)
        delayed = self.pipe.popleft()
        self.rise_mmhg = self.a * self.rise_mmhg + (1.0 - self.a) * self.K * delayed


class Pump:
    """Syringe pump: clamps commands to [0, max_ml_h] and keeps its rate on a missing command."""

    def __init__(self, dialect: ModuleType, max_ml_h: float):
        self.d, self.max_ml_h = dialect, max_ml_h
        self.rate_ml_h = 0.0
        self.volume_ml = 0.0
        self.alarms = 0

    def apply(self, command_ml_h: float | None) -> None:
        """Take a command (None: none arrived, the rate is kept); sets the advisory alarm bits."""
        self.alarms = 0
        if command_ml_h is None:
            return
        if not math.isfinite(command_ml_h):
            self.alarms = self.d.PRESSOR_PUMP_ALARM_INVALID_COMMAND
            return
        clamped = min(max(command_ml_h, 0.0), self.max_ml_h)
        if clamped != command_ml_h:
            self.alarms = self.d.PRESSOR_PUMP_ALARM_OUT_OF_RANGE
        self.rate_ml_h = clamped

    def run(self, Ts_s: float) -> None:
        """Deliver the current rate for one sample period."""
        self.volume_ml += self.rate_ml_h * Ts_s / 3600.0


class Monitor:
    """Patient monitor: optional Gaussian noise (own seed), optional quantum, an update period.

    Between updates ``read`` returns the last value and ``fresh`` False.
    """

    def __init__(self, noise_mmhg: float, quantum_mmhg: float | None, every_ticks: int, seed: int):
        self.noise_mmhg, self.quantum_mmhg, self.every_ticks = noise_mmhg, quantum_mmhg, every_ticks
        self.rng = random.Random(seed)
        self.last_mmhg = math.nan

    def read(self, tick: int, true_mmhg: float) -> tuple[float, bool]:
        """The displayed MAP (mmHg) at ``tick`` and whether it is a new measurement."""
        if tick % self.every_ticks:
            return self.last_mmhg, False
        value = true_mmhg + self.rng.gauss(0.0, self.noise_mmhg)
        if self.quantum_mmhg:
            value = round(value / self.quantum_mmhg) * self.quantum_mmhg
        self.last_mmhg = value
        return value, True
