"""Experimental schedules on a fit from outside the loop (:mod:`research.schedule_sources`, run
when named in its ``--runs``): a fit held, and its K moved afterwards. Not shipped, kept so that
the figures docs/notes/estimation.md gives for them reproduce.

:func:`clamped` puts (K, T, τ) inside a design box (``lpv-truth``, ``lpv-stepfit``, ...).
:class:`KHandover` (``stepfit-twok:...``) moves the fit's K to the incremental one from a given
time ("The frontier, revisited"); :class:`SecantK` (``stepfit-secant:...``) toward the secant gain
the settled loop measures ("A realistic device's fit, and the loop gain").
"""

from __future__ import annotations

import math
from collections import deque

from pressor.runtime.core.scheduling import Schedule, ScheduleInput

__all__ = ["KHandover", "SecantK", "clamped"]

Box = tuple[tuple[float, float], ...]


def clamped(values: tuple[float, ...], box: Box) -> tuple[float, ...]:
    """``values`` (K mmHg/(ml/h), T s, τ s) each clamped to its interval of ``box``."""
    return tuple(min(max(v, lo), hi) for v, (lo, hi) in zip(values, box, strict=True))


def _held(K: float, T_s: float, tau_s: float) -> Schedule:
    return Schedule(K, T_s, tau_s, "nominal", True, True, True, "prior")


class KHandover:
    """Experiment: a fixed schedule (``values`` = (K start, T s, τ s, K later), clamped to
    ``box``) whose K moves from the start's to the later one at ``rate_per_s`` from ``switch_s``
    s on: the start-up dose of one sensitivity, the disturbance rejection of another."""

    source = "nominal"

    def __init__(
        self,
        box: Box,
        values: tuple[float, ...],
        switch_s: float,
        rate_per_s: float,
        sample_period_s: float,
    ) -> None:
        k0, T, tau, k1 = values
        self.k0, self.T, self.tau = clamped((k0, T, tau), box)
        self.k1 = clamped((k1,), box[:1])[0]
        self.switch_s, self.rate, self.ts, self.k = switch_s, rate_per_s, sample_period_s, 0

    def update(self, inputs: ScheduleInput) -> Schedule:
        t = self.k * self.ts
        self.k += 1
        step = self.rate * max(0.0, t - self.switch_s)
        return _held(self.k0 + max(-step, min(step, self.k1 - self.k0)), self.T, self.tau)


class SecantK:
    """Experiment: a held schedule (``values`` = K, T s, τ s) whose K moves, at ``rate_per_s``
    (mmHg/(ml/h) per s, the design's certified K rate), toward the secant gain the loop itself
    measures once it holds the target: (target − the MAP before the infusion) ÷ the mean
    delivered rate over the last ``window_s`` s, recomputed every tick from ``after_s`` s on while
    the window's mean error is within ``settled_mmhg``. The target comes from ``target_mmhg``;
    K stays inside ``box``. The window's sums are kept running (no per-tick pass over it)."""

    source = "nominal"

    def __init__(
        self,
        box: Box,
        values: tuple[float, ...],
        target_mmhg: float,
        rate_per_s: float,
        sample_period_s: float,
        after_s: float = 600.0,
        window_s: float = 300.0,
        settled_mmhg: float = 1.0,
    ) -> None:
        self.K, self.T, self.tau = clamped(tuple(values[:3]), box)
        self.k_lo, self.k_hi = box[0]
        self.target, self.step_ = target_mmhg, rate_per_s * sample_period_s
        self.ts, self.after_s = sample_period_s, after_s
        self.n = round(window_s / sample_period_s)
        self.settled = settled_mmhg
        self.k = 0
        self.y0 = math.nan
        self.window: deque[tuple[float, float]] = deque()  # (delivered ml/h, error mmHg)
        self.u_sum = self.e_sum = 0.0
        self.goal = self.K

    def update(self, inputs: ScheduleInput) -> Schedule:
        t = self.k * self.ts
        self.k += 1
        y, u = inputs.map_mmhg, inputs.delivered_ml_h
        if math.isfinite(y):
            if math.isnan(self.y0):
                self.y0 = y
            self.window.append((u, self.target - y))
            self.u_sum += u
            self.e_sum += self.target - y
            if len(self.window) > self.n:
                u_old, e_old = self.window.popleft()
                self.u_sum -= u_old
                self.e_sum -= e_old
        if t >= self.after_s and len(self.window) == self.n:
            u_mean, e_mean = self.u_sum / self.n, self.e_sum / self.n
            if abs(e_mean) <= self.settled and u_mean > 0.0:
                goal = (self.target - self.y0) / u_mean
                self.goal = min(max(goal, self.k_lo), self.k_hi)
        self.K += max(-self.step_, min(self.step_, self.goal - self.K))
        return _held(self.K, self.T, self.tau)
