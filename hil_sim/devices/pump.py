"""Syringe/volumetric infusion pump model (pure: explicit state, virtual time).

A command (ml/h) is validated, clamped to [0, max_rate], rounded to the pump's rate resolution and
takes effect ``latency_s`` after it was received. The pump integrates the delivered volume, raises
alarms and has its own watchdog:

- ``ALARM_OCCLUSION``: from ``occlusion_start_s`` (for ``occlusion_duration_s``) nothing is delivered.
- ``ALARM_RESERVOIR_EMPTY``: once ``reservoir_ml`` has been delivered the pump stops.
- ``ALARM_WATCHDOG``: no valid command for ``watchdog_s`` → the pump runs at ``safe_rate_ml_h`` and
  holds the alarm until the next valid command, which resumes normal operation.
- ``ALARM_INVALID_COMMAND``: the last command was not finite (ignored; does not feed the watchdog).
- ``ALARM_OUT_OF_RANGE``: the last command was outside [0, max] and was clamped.

Injected faults (``--fault pump-*``, set per tick by the world through :meth:`Pump.inject`):
occlusion (nothing flows, ``ALARM_OCCLUSION``), empty reservoir (nothing flows,
``ALARM_RESERVOIR_EMPTY`` until a new syringe at the end of the window), a delivery factor
(delivered = factor × set rate; ``delivered_ml_h`` reports the measured delivery) and
:meth:`Pump.feed_watchdog` for a pump that acknowledges commands without applying them.

The alarm bit values are the link protocol's (:mod:`pressor.contracts.faults`), one definition for both ends.

The delivered rate over a step may change inside it (latency not a multiple of the step, reservoir
running dry): :meth:`Pump.advance` returns the exact mean rate over the step, which is what the
patient's exact delay buffer consumes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pressor.contracts.faults import PUMP_ALARM_INVALID_COMMAND as ALARM_INVALID_COMMAND
from pressor.contracts.faults import PUMP_ALARM_OCCLUSION as ALARM_OCCLUSION
from pressor.contracts.faults import PUMP_ALARM_OUT_OF_RANGE as ALARM_OUT_OF_RANGE
from pressor.contracts.faults import PUMP_ALARM_RESERVOIR_EMPTY as ALARM_RESERVOIR_EMPTY
from pressor.contracts.faults import PUMP_ALARM_WATCHDOG as ALARM_WATCHDOG

#: ``math.isfinite`` without the module attribute lookup (a command a tick)
_isfinite = math.isfinite


@dataclass(frozen=True)
class PumpConfig:
    """Pump settings (all validated by the scenario loader; the constructor re-checks).

    Attributes
    ----------
    max_rate_ml_h
        Upper limit (ml/h).
    resolution_ml_h
        Rate step (ml/h); 0 means continuous.
    latency_s
        Delay from a command's arrival to its effect (s).
    watchdog_s
        No valid command for this long → safe rate + alarm (s); ``inf`` disables it.
    safe_rate_ml_h
        Rate while the watchdog has tripped (ml/h).
    reservoir_ml
        Drug volume available (ml).
    occlusion_start_s, occlusion_duration_s
        Occlusion window (s); ``None`` start means no occlusion.
    """

    max_rate_ml_h: float = 120.0
    resolution_ml_h: float = 0.0
    latency_s: float = 0.0
    watchdog_s: float = 5.0
    safe_rate_ml_h: float = 0.0
    reservoir_ml: float = 1000.0
    occlusion_start_s: float | None = None
    occlusion_duration_s: float = math.inf

    def __post_init__(self) -> None:
        if not 0.0 < self.max_rate_ml_h <= 10000.0:
            raise ValueError(f"max_rate_ml_h={self.max_rate_ml_h!r} outside (0, 10000] ml/h")
        if self.resolution_ml_h < 0.0 or self.latency_s < 0.0 or self.watchdog_s <= 0.0:
            raise ValueError("resolution_ml_h, latency_s must be >= 0 and watchdog_s > 0")
        if not 0.0 <= self.safe_rate_ml_h <= self.max_rate_ml_h:
            raise ValueError(f"safe_rate_ml_h={self.safe_rate_ml_h!r} outside [0, max_rate_ml_h]")
        if self.reservoir_ml <= 0.0:
            raise ValueError(f"reservoir_ml={self.reservoir_ml!r} must be > 0 ml")


class Pump:
    """The pump's state machine; time advances only through :meth:`advance`.

    Parameters
    ----------
    config
        :class:`PumpConfig`.
    """

    def __init__(self, config: PumpConfig | None = None) -> None:
        self.config = config or PumpConfig()
        self.time_s = 0.0
        self.rate_ml_h = 0.0  # the rate set on the mechanism (before occlusion/reservoir)
        self.delivered_ml_h = 0.0  # the rate actually flowing at time_s
        self.volume_ml = 0.0
        self.alarms = 0
        self.commands_out_of_range = 0
        self._pending: list[tuple[float, float]] = []  # (effective time s, rate ml/h)
        self._last_valid_s = 0.0
        self._watchdog = False
        self._dry = False  # the real reservoir ran out (never refilled)
        self._inj_occluded = False
        self._inj_empty = False
        self._inj_factor = 1.0

    def inject(self, occluded: bool, empty: bool, factor: float) -> None:
        """Set the injected fault state for the next :meth:`advance` (see the module docstring)."""
        self._inj_occluded = occluded
        self._inj_empty = empty
        self._inj_factor = factor

    def feed_watchdog(self) -> None:
        """A command was received but not applied (injected ``pump-ignore``)."""
        self._last_valid_s = self.time_s

    def command(self, rate_ml_h: float) -> float:
        """Receive a command at the current time; return the rate it will set (ml/h).

        A non-finite command is ignored (``ALARM_INVALID_COMMAND``) and returns NaN.
        """
        cfg = self.config
        self.alarms &= ~(ALARM_INVALID_COMMAND | ALARM_OUT_OF_RANGE)
        if not _isfinite(rate_ml_h):
            self.alarms |= ALARM_INVALID_COMMAND
            return math.nan
        rate = min(max(rate_ml_h, 0.0), cfg.max_rate_ml_h)
        if rate != rate_ml_h:
            self.alarms |= ALARM_OUT_OF_RANGE
            self.commands_out_of_range += 1
        if cfg.resolution_ml_h > 0.0:
            rate = min(round(rate / cfg.resolution_ml_h) * cfg.resolution_ml_h, cfg.max_rate_ml_h)
        self._last_valid_s = self.time_s
        if self._watchdog:
            self._watchdog = False
            self.alarms &= ~ALARM_WATCHDOG
            self._pending.clear()
        if cfg.latency_s == 0.0:
            self.rate_ml_h = rate
        else:
            self._pending.append((self.time_s + cfg.latency_s, rate))
        return rate

    def _flowing(self, t_s: float, rate: float) -> float:
        cfg = self.config
        if self._inj_occluded:
            return 0.0
        if cfg.occlusion_start_s is not None and (
            cfg.occlusion_start_s <= t_s < cfg.occlusion_start_s + cfg.occlusion_duration_s
        ):
            return 0.0
        return rate

    def advance(self, dt_s: float) -> float:
        """Run for ``dt_s`` seconds; return the mean delivered rate over them (ml/h)."""
        cfg = self.config
        t, t_end = self.time_s, self.time_s + dt_s
        if not self._watchdog and t_end - self._last_valid_s >= cfg.watchdog_s - 1e-9:
            self._watchdog = True
            self._pending.clear()
            self.rate_ml_h = cfg.safe_rate_ml_h
            self.alarms |= ALARM_WATCHDOG
        flow = self.rate_ml_h * self._inj_factor
        if (
            not self._pending
            and cfg.occlusion_start_s is None
            and not (self._inj_occluded or self._dry or self._inj_empty)
            and t < t_end - 1e-12
            and not (
                flow > 0.0 and flow * (t_end - t) / 3600.0 >= cfg.reservoir_ml - self.volume_ml
            )
        ):
            # The common case, one segment over the whole step at the set rate: what the general
            # loop below computes for it, in the same operations, without its bookkeeping.
            self.volume_ml += flow * (t_end - t) / 3600.0
            self.time_s = t_end
            self.alarms &= ~(ALARM_OCCLUSION | ALARM_RESERVOIR_EMPTY)
            self.delivered_ml_h = flow
            return flow
        volume_ml_h_s = 0.0
        n_segments = 0
        full_flow: float | None = None
        # Piecewise over the step: pending rate changes, the occlusion edges, the reservoir running dry.
        while t < t_end - 1e-12:
            seg_end = t_end
            if self._pending and self._pending[0][0] < seg_end:
                seg_end = max(self._pending[0][0], t)
            occ = cfg.occlusion_start_s
            if occ is not None:
                for edge in (occ, occ + cfg.occlusion_duration_s):
                    if t < edge < seg_end:
                        seg_end = edge
            flow = self._flowing(t, self.rate_ml_h) * self._inj_factor
            if self._dry or self._inj_empty:
                flow = 0.0
            seg = seg_end - t
            left_ml = cfg.reservoir_ml - self.volume_ml
            if flow > 0.0 and flow * seg / 3600.0 >= left_ml:
                seg = left_ml * 3600.0 / flow
                seg_end = t + seg
                self._dry = True
            volume_ml_h_s += flow * seg
            n_segments += 1
            full_flow = flow if (t == self.time_s and seg_end == t_end) else None
            self.volume_ml += flow * seg / 3600.0
            t = seg_end
            while self._pending and self._pending[0][0] <= t + 1e-12:
                self.rate_ml_h = self._pending.pop(0)[1]
        self.time_s = t_end
        flow_now = self._flowing(t_end, self.rate_ml_h) * self._inj_factor
        if self._inj_occluded or self._flowing(t_end, 1.0) == 0.0:
            self.alarms |= ALARM_OCCLUSION  # line occluded: the pump's pressure sensor trips
        else:
            self.alarms &= ~ALARM_OCCLUSION
        if self._dry or self._inj_empty:
            self.alarms |= ALARM_RESERVOIR_EMPTY
        else:
            self.alarms &= ~ALARM_RESERVOIR_EMPTY  # a new syringe after an injected empty
        self.delivered_ml_h = 0.0 if self.alarms & ALARM_RESERVOIR_EMPTY else flow_now
        if n_segments == 1 and full_flow is not None:
            return full_flow  # one segment over the whole step: the rate itself, no round-off
        return volume_ml_h_s / dt_s
