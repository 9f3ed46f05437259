"""The safety supervisor's checks of one tick's inputs: the MAP sample, the scheduling
parameters, the online estimate and the pump's status, each turned into fault bits.

:class:`InputChecks` keeps what the checks need from earlier ticks (the previous MAP and scheduling
parameters, the flatline rules' window, since when a pump mismatch or an estimate outside the
design box has lasted); the supervisor (:mod:`pressor.runtime.core.supervisor`) calls it once per
tick and decides the state from the bits. Pure: no I/O, no clock (every call gets the time, s).
What each fault means and its detection bound: :mod:`pressor.runtime.core.supervisor_config`.
"""

from __future__ import annotations

import math

from pressor.runtime.core.flatline import FlatlineRules
from pressor.runtime.core.supervisor_config import Fault, SupervisorConfig
from pressor.runtime.core.supervisor_io import SupervisorInput

#: the fault bits as plain ints (an IntFlag's arithmetic runs Python-level enum code)
_ESTIMATE_OUT_OF_BOX = int(Fault.ESTIMATE_OUT_OF_BOX)
_ESTIMATOR_FALLBACK = int(Fault.ESTIMATOR_FALLBACK)
_MAP_FLATLINE, _MAP_NAN = int(Fault.MAP_FLATLINE), int(Fault.MAP_NAN)
_MAP_RANGE, _MAP_SPIKE = int(Fault.MAP_RANGE), int(Fault.MAP_SPIKE)
_PUMP_ALARM, _PUMP_MISMATCH = int(Fault.PUMP_ALARM), int(Fault.PUMP_MISMATCH)
_SCHED_INVALID, _SCHED_OUT_OF_BOX = int(Fault.SCHED_INVALID), int(Fault.SCHED_OUT_OF_BOX)
_SCHED_RATE, _SENSOR_QUALITY = int(Fault.SCHED_RATE), int(Fault.SENSOR_QUALITY)

#: slack (s) on time comparisons so that k·Ts sums reach a bound that is a whole number of ticks
_EPS_S = 1e-9

#: ``math.isfinite`` without the module attribute lookup (the per-tick path)
_isfinite = math.isfinite


class InputChecks:
    """The input checks of one run and the history they keep (see the module docstring).

    Parameters
    ----------
    config
        The supervisor's limits and timings.
    """

    def __init__(self, config: SupervisorConfig) -> None:
        cfg = self.config = config
        self._prev_map: float | None = None
        self._flat = (
            FlatlineRules(
                cfg.sensor_noise_mmhg,
                cfg.flatline_s,
                cfg.flatline_eps_mmhg,
                cfg.flatline_window,
                cfg.flatline_ratio,
            )
            if cfg.sensor_noise_mmhg > 0.0
            else None
        )
        self._flat_fault = 0  # the flatline verdict of the last new sample, held between them
        # the scheduling checks' configuration, unpacked once (sched() runs every tick): whether
        # any is on, the box as (K lo, K hi, T lo, T hi, tau lo, tau hi), and the rate bounds
        # times their tolerance ((tol * b) * dt below is the same product as tol * b * dt)
        self._sched_on = bool(cfg.sched_required or cfg.sched_box or cfg.sched_rate_bounds)
        box = cfg.sched_box
        self._sched_box: tuple[float, ...] | None = (
            None if box is None else tuple(v for pair in box for v in pair)
        )
        bounds = cfg.sched_rate_bounds
        tol = cfg.sched_rate_tolerance
        self._sched_rate: tuple[float, ...] | None = (
            None if bounds is None else tuple(tol * b for b in bounds)
        )
        self._prev_sched: tuple[float, float, float] | None = None
        self._prev_sched_s = 0.0
        self._mismatch_since_s: float | None = None
        self._out_of_box_since_s: float | None = None
        # the largest delivered rate a pump status may report (ml/h; float32 on the wire)
        pump_max = cfg.max_rate_ml_h if cfg.pump_max_ml_h is None else cfg.pump_max_ml_h
        self._pump_max_ml_h = pump_max * (1.0 + 1e-6)

    def map(self, now_s: float, map_mmhg: float, quality: int, new: bool) -> int:
        """``SENSOR_QUALITY``, ``MAP_NAN``, ``MAP_RANGE``, ``MAP_SPIKE`` and, on a ``new``
        sample, ``MAP_FLATLINE`` (held between new samples)."""
        cfg = self.config
        faults = 0
        if quality & cfg.quality_mask:
            faults |= _SENSOR_QUALITY
        if not _isfinite(map_mmhg):
            return faults | _MAP_NAN
        if not cfg.map_min_mmhg <= map_mmhg <= cfg.map_max_mmhg:
            return faults | _MAP_RANGE
        if self._prev_map is not None and abs(map_mmhg - self._prev_map) > cfg.spike_mmhg:
            faults |= _MAP_SPIKE
        self._prev_map = map_mmhg
        if self._flat is not None:
            if new:
                self._flat_fault = _MAP_FLATLINE if self._flat.update(now_s, map_mmhg) else 0
            faults |= self._flat_fault
        return faults

    def sched(self, now_s: float, K: float, T_s: float, tau_s: float, valid: bool) -> int:
        """``SCHED_INVALID``, ``SCHED_OUT_OF_BOX`` and ``SCHED_RATE``."""
        # written out for the three parameters: this runs every tick of every trial patient (the
        # box and the rate bounds were unpacked once, in __init__)
        if not self._sched_on:
            return 0
        if not (valid and _isfinite(K) and _isfinite(T_s) and _isfinite(tau_s)):
            self._prev_sched = None
            return _SCHED_INVALID
        faults = 0
        box = self._sched_box
        if box is not None:
            k_lo, k_hi, t_lo, t_hi, d_lo, d_hi = box
            if not (k_lo <= K <= k_hi and t_lo <= T_s <= t_hi and d_lo <= tau_s <= d_hi):
                faults |= _SCHED_OUT_OF_BOX
        prev = self._prev_sched
        rate = self._sched_rate
        if rate is not None and prev is not None:
            dt = now_s - self._prev_sched_s
            if dt > 0.0:
                r_k, r_t, r_d = rate  # tolerance x bound, per parameter
                if (
                    abs(K - prev[0]) > r_k * dt
                    or abs(T_s - prev[1]) > r_t * dt
                    or abs(tau_s - prev[2]) > r_d * dt
                ):
                    faults |= _SCHED_RATE
        if prev is None or now_s > self._prev_sched_s:
            self._prev_sched = (K, T_s, tau_s)
            self._prev_sched_s = now_s
        return faults

    def estimate(self, now_s: float, inp: SupervisorInput) -> int:
        """``ESTIMATOR_FALLBACK`` and ``ESTIMATE_OUT_OF_BOX`` (the box held for estimate_box_s)."""
        cfg = self.config
        faults = 0 if inp.estimate_healthy else _ESTIMATOR_FALLBACK
        box = self._sched_box
        if box is None:
            return faults
        k_lo, k_hi, t_lo, t_hi, d_lo, d_hi = box
        if k_lo <= inp.K <= k_hi and t_lo <= inp.T_s <= t_hi and d_lo <= inp.tau_s <= d_hi:
            self._out_of_box_since_s = None
            return faults
        if self._out_of_box_since_s is None:
            self._out_of_box_since_s = now_s
        if now_s - self._out_of_box_since_s >= cfg.estimate_box_s - _EPS_S:
            faults |= _ESTIMATE_OUT_OF_BOX
        return faults

    def pump(self, now_s: float, delivered: float, alarms: int, sent: float) -> int:
        """``PUMP_MISMATCH`` (a rate no pump delivers at once; off ``sent``, the last command,
        for ``pump_mismatch_s``) and ``PUMP_ALARM``; a tick without a status is neither."""
        cfg = self.config
        if delivered != delivered:  # no fresh status: neither fault nor evidence of health
            return 0
        if not 0.0 <= delivered <= self._pump_max_ml_h:  # no pump delivers that: inf, < 0, > max
            self._mismatch_since_s = now_s
            return _PUMP_MISMATCH | (_PUMP_ALARM if alarms & cfg.pump_alarm_mask else 0)
        faults = 0
        if alarms & cfg.pump_alarm_mask:
            # the held command stays the runtime's own: a status (the watchdog bit's included)
            # never sets what the runtime commands (docs/PROTOCOL.md, "Quality and alarm bits")
            faults |= _PUMP_ALARM
        if alarms & cfg.pump_alarm_mask or abs(delivered - sent) <= max(
            cfg.pump_mismatch_abs_ml_h, cfg.pump_mismatch_rel * abs(sent)
        ):
            self._mismatch_since_s = None
        else:
            if self._mismatch_since_s is None:
                self._mismatch_since_s = now_s
            if now_s - self._mismatch_since_s >= cfg.pump_mismatch_s - _EPS_S:
                faults |= _PUMP_MISMATCH
        return faults
