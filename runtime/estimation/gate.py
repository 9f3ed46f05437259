"""Sample gate: which MAP samples may enter the estimator (pure, O(1) per tick, no allocation).

A sample is rejected, with the first matching reason, when it is

``nonfinite``
    NaN or ±inf (a monitor with no value, a corrupted reading);
``quality``
    any monitor quality bit is set (:data:`pressor.contracts.faults.QUALITY_INVALID`, ``QUALITY_WAVEFORM``);
``range``
    outside ``[map_min_mmhg, map_max_mmhg]`` (a fast-flush to the bag pressure, a transducer open to
    air, an out-of-range value);
``spike``
    more than ``max_jump_mmhg`` plus ``slew_mmhg_per_s`` × (time since it) away from the last
    accepted sample (a MAP cannot move tens of mmHg within a second); the allowance grows while
    samples are rejected, so a real but sudden shift cannot lock the estimator out for ever;
``flatline``
    the same value, bit for bit, for at least ``flatline_s`` (a frozen transducer or monitor).
    A noise-free simulated MAP can also sit still; while it does it carries no information, so
    holding the estimate loses nothing.

The gate never changes a sample; it only says whether the estimator may use it.
"""

from __future__ import annotations

import math

REASONS = ("ok", "nonfinite", "quality", "range", "spike", "flatline")

#: ``math.isfinite`` without the module attribute lookup (a sample a tick)
_isfinite = math.isfinite


class SampleGate:
    """Accept or reject MAP samples, one per tick.

    Parameters
    ----------
    sample_period_s
        Tick period (s), > 0.
    map_min_mmhg, map_max_mmhg
        Physiological range (mmHg) of an acceptable MAP, min < max.
    max_jump_mmhg
        Largest accepted change from the last accepted sample one tick later (mmHg), > 0.
    slew_mmhg_per_s
        Extra allowance per second since the last accepted sample (mmHg/s), >= 0.
    flatline_s
        Bit-identical run length from which samples are rejected (s), > 0.

    Attributes
    ----------
    reason
        Why the last sample was rejected (one of :data:`REASONS`; ``"ok"`` when accepted).
    rejected
        Number of rejected samples since construction.
    """

    def __init__(
        self,
        sample_period_s: float = 0.1,
        map_min_mmhg: float = 20.0,
        map_max_mmhg: float = 200.0,
        max_jump_mmhg: float = 8.0,
        slew_mmhg_per_s: float = 2.0,
        flatline_s: float = 10.0,
    ) -> None:
        for name, value in (
            ("sample_period_s", sample_period_s),
            ("max_jump_mmhg", max_jump_mmhg),
            ("flatline_s", flatline_s),
        ):
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name}={value!r} must be a finite number > 0")
        if not (math.isfinite(slew_mmhg_per_s) and slew_mmhg_per_s >= 0.0):
            raise ValueError(f"slew_mmhg_per_s={slew_mmhg_per_s!r} must be finite and >= 0")
        if not (math.isfinite(map_min_mmhg) and math.isfinite(map_max_mmhg)):
            raise ValueError("map_min_mmhg and map_max_mmhg must be finite")
        if map_min_mmhg >= map_max_mmhg:
            raise ValueError(
                f"map_min_mmhg={map_min_mmhg!r} must be < map_max_mmhg={map_max_mmhg!r}"
            )
        self._lo = float(map_min_mmhg)
        self._hi = float(map_max_mmhg)
        self._jump = float(max_jump_mmhg)
        self._slew_per_tick = float(slew_mmhg_per_s) * sample_period_s
        self._flat_ticks = max(2, round(flatline_s / sample_period_s))
        self._last = math.nan  # last accepted sample (mmHg)
        self._since = 0  # ticks since the last accepted sample
        self._prev = math.nan  # previous raw sample (mmHg)
        self._run = 0  # length of the current bit-identical run
        self.reason = "ok"
        self.rejected = 0

    def accept(self, map_mmhg: float, quality: int) -> bool:
        """Whether ``map_mmhg`` (mmHg) with monitor ``quality`` bits may enter the estimator."""
        self._since += 1
        reason = "ok"
        if not _isfinite(map_mmhg):
            reason = "nonfinite"
            self._run = 0
        else:
            self._run = self._run + 1 if map_mmhg == self._prev else 1
            if quality:
                reason = "quality"
            elif not self._lo <= map_mmhg <= self._hi:
                reason = "range"
            elif self._run >= self._flat_ticks:
                reason = "flatline"
            elif (
                self._last == self._last  # not NaN: an anchor exists
                and abs(map_mmhg - self._last) > self._jump + self._slew_per_tick * self._since
            ):
                reason = "spike"
        self._prev = map_mmhg
        self.reason = reason
        if reason != "ok":
            self.rejected += 1
            return False
        self._last = map_mmhg
        self._since = 0
        return True
