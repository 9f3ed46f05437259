"""Arterial-line MAP monitor: sampling, quantisation, seeded noise and line artifacts.

The monitor samples the true MAP every ``period_s`` (sample-and-hold between samples: a reading
between two monitor updates repeats the last value with ``QUALITY_HELD`` added, as a monitor slower
than the loop reports it on the link, docs/PROTOCOL.md), adds
Gaussian noise (σ = ``noise_std_mmhg``, from the patient's own seeded PCG64 stream, drawn in blocks
so the sequence does not depend on how the loop is driven) and rounds to ``quantum_mmhg``.
Artifacts, each switched on by the scenario for a time window:

``flush``
    Fast-flush of the line: reading jumps to the flush-bag pressure ``level_mmhg`` (default 300).
``damping``
    Over-damped line (air bubble, clot): the reading lags the truth, first order, ``time_const_s``.
``disconnect``
    Transducer open to air: reading ≈ ``level_mmhg`` (default 0) plus noise.
``monitor_fault``
    The monitor reports no value: NaN with ``QUALITY_INVALID`` set.

Injected faults (``--fault sensor-*``, :mod:`pressor.hil_sim.scenarios.faults`) add three more kinds:

``nan``
    The reading is NaN *without* a quality flag (a corrupted value).
``flatline``
    The reading sticks at the last value output before the window (transducer / monitor frozen).
``range``
    The reading is ``level_mmhg`` (default 400), outside any physiological range.

Only the monitor's own fault is flagged in ``quality``: a real monitor cannot tell a flush or a
disconnection from physiology; the runtime's supervisor has to detect those. An artifact with a
finite ``flag_after_s`` also sets ``QUALITY_WAVEFORM`` from ``start_s + flag_after_s`` on: the
monitor's waveform check (a frozen or over-damped arterial trace loses its pulsatility, which the
beat-by-beat monitor sees and a mean pressure alone does not). Shipped scenario artifacts leave
it at ``inf`` (never flagged), as before.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pressor.contracts.faults import QUALITY_HELD, QUALITY_INVALID, QUALITY_WAVEFORM

ARTIFACT_KINDS = ("flush", "damping", "disconnect", "monitor_fault", "nan", "flatline", "range")
_NOISE_BLOCK = 4096


@dataclass(frozen=True)
class Artifact:
    """A line artifact active on [start_s, start_s + duration_s).

    Attributes
    ----------
    kind
        One of :data:`ARTIFACT_KINDS`.
    start_s, duration_s
        Window (s).
    level_mmhg
        Reading for ``flush`` / ``disconnect`` (mmHg).
    time_const_s
        Lag of ``damping`` (s).
    flag_after_s
        Delay (s) after ``start_s`` from which the monitor flags ``QUALITY_WAVEFORM``; ``inf``:
        never.
    """

    kind: str
    start_s: float
    duration_s: float
    level_mmhg: float = math.nan
    time_const_s: float = 20.0
    flag_after_s: float = math.inf

    def __post_init__(self) -> None:
        if self.kind not in ARTIFACT_KINDS:
            raise ValueError(f"artifact kind {self.kind!r} not one of {ARTIFACT_KINDS}")
        if math.isnan(self.level_mmhg):
            default = {"flush": 300.0, "range": 400.0}.get(self.kind, 0.0)
            object.__setattr__(self, "level_mmhg", default)

    def active(self, t_s: float) -> bool:
        return self.start_s <= t_s < self.start_s + self.duration_s


@dataclass(frozen=True)
class SensorConfig:
    """Monitor settings: ``period_s`` (s), ``quantum_mmhg`` (0 = none), ``noise_std_mmhg``."""

    period_s: float = 0.1
    quantum_mmhg: float = 0.0
    noise_std_mmhg: float = 0.0
    artifacts: tuple[Artifact, ...] = ()


class Sensor:
    """The monitor's state; :meth:`read` is called once per world tick, in tick order.

    Parameters
    ----------
    config
        :class:`SensorConfig`.
    rng
        The seeded generator for the noise (used only if ``noise_std_mmhg`` > 0).
    """

    def __init__(self, config: SensorConfig, rng: np.random.Generator | None = None) -> None:
        self.config = config
        self._rng = rng
        self._noise: list[float] = []  # a block of draws, as Python floats (indexing numpy is slow)
        self._noise_i = 0
        self._next_sample_s = 0.0
        self._held = (math.nan, QUALITY_INVALID)
        self._damped: float | None = None
        self._last_t: float | None = None
        self._frozen: dict[int, float] = {}
        self._artifacts: Sequence[Artifact] = config.artifacts
        if config.noise_std_mmhg > 0.0 and rng is None:
            raise ValueError("a noisy sensor needs a seeded rng")

    def _next_noise(self) -> float:
        if self._noise_i >= len(self._noise):
            assert self._rng is not None
            block = self._rng.standard_normal(_NOISE_BLOCK) * self.config.noise_std_mmhg
            self._noise = block.tolist()
            self._noise_i = 0
        v = self._noise[self._noise_i]
        self._noise_i += 1
        return v

    def read(self, t_s: float, true_map_mmhg: float) -> tuple[float, int]:
        """The monitor's reading at ``t_s``: ``(map_mmhg, quality flags)``; between two monitor
        updates the last reading with ``QUALITY_HELD`` added."""
        cfg = self.config
        # The damped line filters continuously, sampled or not.
        if self._damped is None or self._last_t is None or not self._artifacts:
            self._damped = true_map_mmhg  # (no artifacts: no damping, and no generator per tick)
        else:
            tc = next(
                (a.time_const_s for a in self._artifacts if a.kind == "damping" and a.active(t_s)),
                None,
            )
            if tc is None:
                self._damped = true_map_mmhg
            else:
                self._damped += (1.0 - math.exp(-(t_s - self._last_t) / tc)) * (
                    true_map_mmhg - self._damped
                )
        self._last_t = t_s
        if t_s + 1e-9 < self._next_sample_s:
            value, quality = self._held
            return value, quality | QUALITY_HELD
        self._next_sample_s += cfg.period_s
        value = self._damped
        quality = 0
        frozen: float | None = None
        for a in self._artifacts:
            if a.active(t_s):
                if t_s >= a.start_s + a.flag_after_s:
                    quality |= QUALITY_WAVEFORM
                if a.kind == "monitor_fault":
                    self._held = (math.nan, QUALITY_INVALID)
                    return self._held
                if a.kind == "nan":
                    self._held = (math.nan, quality)
                    return self._held
                if a.kind == "range":
                    self._held = (a.level_mmhg, quality)
                    return self._held
                if a.kind == "flatline":
                    frozen = self._frozen.setdefault(id(a), self._held[0])
                if a.kind in ("flush", "disconnect"):
                    value = a.level_mmhg
        if frozen is not None:
            self._held = (frozen, quality)
            return self._held
        if cfg.noise_std_mmhg > 0.0:
            value += self._next_noise()
        if cfg.quantum_mmhg > 0.0:
            value = round(value / cfg.quantum_mmhg) * cfg.quantum_mmhg
        self._held = (value, quality)
        return self._held
