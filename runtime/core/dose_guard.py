"""The drug library's limits on the final pump command (the last step of the supervisor).

:class:`DoseGuard` sees every command the supervisor is about to output - after the controller,
any plugin controller, the supervisor's own state logic and its [0, max_rate_ml_h] clamp - and:

1. cuts it to what the hourly dose maximum still allows: the volume commanded over the sliding
   hour (this tick's included) never exceeds ``max_ml_per_hour`` (``DOSE_HOUR_LIMIT``);
2. cuts it to the hard dose maximum ``hard_max_ml_h`` (``DOSE_HARD_LIMIT``);
3. flags a command above the soft maximum ``soft_max_ml_h`` (``DOSE_SOFT_LIMIT``, advisory).

All three raise the alarm and are counted as detections; none changes the supervisor's state
(the command is cut, the loop keeps running; a held command stays cut). The limits are the
library's dose limits converted to ml/h once (:meth:`pressor.runtime.inputs.drug_library.DrugEntry.limits`,
rounded down): a command at or below ``hard_max_ml_h`` is at or below the hard dose maximum.
The hour is counted in ticks of the loop period; each tick's volume is its command times the
period (the pump runs the command until the next one).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

#: fault bits, the same values as :class:`pressor.runtime.core.supervisor_config.Fault` (no import cycle)
DOSE_HARD_LIMIT = 1 << 18
DOSE_SOFT_LIMIT = 1 << 19
DOSE_HOUR_LIMIT = 1 << 20

_HOUR_S = 3600.0


@dataclass(frozen=True)
class DoseLimits:
    """One drug's limits at one concentration and weight, in ml/h (what the supervisor compares).

    Defined here, with the guard that enforces it, not in :mod:`pressor.runtime.inputs.drug_library` (which
    builds it): the core imports nothing from the inputs above it.

    Attributes
    ----------
    hard_max_ml_h
        Largest command (ml/h): the hard dose maximum, rounded down.
    soft_max_ml_h
        Commands above it (ml/h) raise the advisory ``DOSE_SOFT_LIMIT``.
    max_ml_per_hour
        Largest volume (ml) commanded over any sliding hour: the hourly dose maximum.
    concentration_ug_ml
        The syringe (µg/ml).
    weight_kg
        The patient's weight (kg), or ``None`` when not given (limits in µg/min).
    """

    hard_max_ml_h: float
    soft_max_ml_h: float
    max_ml_per_hour: float
    concentration_ug_ml: float
    weight_kg: float | None = None


class DoseGuard:
    """Hard, soft and hourly dose limits on the pump command (see the module docstring).

    Parameters
    ----------
    limits
        The limits in ml/h (:class:`DoseLimits`).
    sample_period_s
        The loop period (s): one command per period.
    """

    def __init__(self, limits: DoseLimits, sample_period_s: float) -> None:
        self.limits = limits
        self.period_s = sample_period_s
        self._ticks = max(1, round(_HOUR_S / sample_period_s))
        self.reset()

    def reset(self) -> None:
        """Forget the hour's history."""
        self._window: deque[float] = deque(maxlen=self._ticks)
        self._sum_ml = 0.0
        self._since_exact = 0

    @property
    def hour_volume_ml(self) -> float:
        """Volume (ml) commanded over the last hour (the ticks in the window)."""
        return max(self._sum_ml, 0.0)

    def limit(self, command_ml_h: float) -> tuple[float, int]:
        """The command (ml/h) cut to the limits, and the fault bits raised; records the tick.

        Parameters
        ----------
        command_ml_h
            The supervisor's command, finite and >= 0.
        """
        lim = self.limits
        faults = 0
        dt_h = self.period_s / _HOUR_S
        window = self._window
        leaving = window[0] if len(window) == self._ticks else 0.0
        room_ml = lim.max_ml_per_hour - (self._sum_ml - leaving)
        hour_cap = max(room_ml, 0.0) / dt_h * (1.0 - 1e-12)
        command = command_ml_h
        if command > hour_cap:
            command = hour_cap
            faults |= DOSE_HOUR_LIMIT
        if command > lim.hard_max_ml_h:
            command = lim.hard_max_ml_h
            faults |= DOSE_HARD_LIMIT
        if command > lim.soft_max_ml_h:
            faults |= DOSE_SOFT_LIMIT
        volume = command * dt_h
        window.append(volume)
        self._sum_ml += volume - leaving
        self._since_exact += 1
        if self._since_exact >= self._ticks:  # no drift of the running sum over long runs
            self._sum_ml = math.fsum(window)
            self._since_exact = 0
        return command, faults
