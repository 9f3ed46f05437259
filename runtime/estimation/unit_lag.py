"""The unit-gain patients the cautious start reads its evidence against."""

from __future__ import annotations

import math

__all__ = ["UnitLag"]


class UnitLag:
    """A unit-gain first-order lag with a delay, driven by the delivered rate's history (exact
    discretisation for a rate held over each tick; the delay read with linear interpolation),
    and optionally a second lag behind it (an effect site; its input held over the tick)."""

    __slots__ = ("a", "b", "k", "f", "y", "a2", "b2", "y2")

    def __init__(
        self, T_s: float, tau_s: float, sample_period_s: float, lag2_s: float | None = None
    ) -> None:
        self.a = math.exp(-sample_period_s / T_s)
        self.b = 1.0 - self.a
        d = tau_s / sample_period_s  # the delay in ticks: whole ticks k and the fraction f
        self.k = int(d)
        self.f = d - self.k
        self.y = 0.0
        self.a2 = None if lag2_s is None else math.exp(-sample_period_s / lag2_s)
        self.b2 = 0.0 if self.a2 is None else 1.0 - self.a2
        self.y2 = 0.0

    @property
    def response(self) -> float:
        """The answer of the last :meth:`step` (the effect site's, if there is one)."""
        return self.y if self.a2 is None else self.y2

    def step(self, hist: list[float], head: int) -> float:
        n = len(hist)
        i = (head - 1 - self.k) % n
        j = (i - 1) % n
        u_i = hist[i]
        u = u_i + (hist[j] - u_i) * self.f
        self.y = y = self.a * self.y + self.b * u
        a2 = self.a2
        if a2 is None:
            return y
        self.y2 = y2 = a2 * self.y2 + self.b2 * y
        return y2
