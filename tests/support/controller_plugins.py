"""Controllers defined outside the project, loaded by ``--controller FILE.py:CLASS[:ARGS]`` (or
``tests.support.controller_plugins:CLASS``): a plain PI one, and broken ones the loader and the supervisor
must catch."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class Status:
    saturated: bool = False
    rho_clamped: bool = False
    rho_rate_limited: bool = False


class PlainPI:
    """A fixed-gain PI (ml/h per mmHg, ml/h per mmHg·s) with a clamp to [0, max_rate_ml_h]."""

    def __init__(
        self, sample_period_s: float = 0.1, kp: float = 0.5, ki: float = 0.01, max_rate_ml_h=120.0
    ) -> None:
        self.sample_period_s = sample_period_s
        self.max_rate_ml_h = float(max_rate_ml_h)
        self.kp, self.ki = kp, ki
        self.status = Status()
        self.reset()

    def reset(self) -> None:
        self.integral = 0.0

    def step(self, map_mmhg: float, target_mmhg: float, K: float, T: float, tau: float) -> float:
        if map_mmhg != map_mmhg:
            return self.kp * 0.0 + self.integral
        error = target_mmhg - map_mmhg
        u = self.kp * error + self.integral + self.ki * self.sample_period_s * error
        self.status.saturated = not 0.0 <= u <= self.max_rate_ml_h
        if not self.status.saturated:
            self.integral += self.ki * self.sample_period_s * error
        return min(max(u, 0.0), self.max_rate_ml_h)


class Runaway(PlainPI):
    """Asks for 1e9 ml/h every tick: the supervisor must clamp it and raise the alarm."""

    def step(self, map_mmhg: float, target_mmhg: float, K: float, T: float, tau: float) -> float:
        return 1e9


class Raises(PlainPI):
    """Raises at its ``at``-th step."""

    def __init__(self, sample_period_s: float = 0.1, at: int = 20) -> None:
        super().__init__(sample_period_s)
        self.at, self.n = at, 0

    def step(self, map_mmhg: float, target_mmhg: float, K: float, T: float, tau: float) -> float:
        self.n += 1
        if self.n >= self.at:
            raise ZeroDivisionError("plugin bug")
        return 1.0


class NoStatus:
    """No ``status`` and no ``reset``."""

    sample_period_s = 0.1
    max_rate_ml_h = 120.0

    def step(self, map_mmhg: float, target_mmhg: float, K: float, T: float, tau: float) -> float:
        return 0.0


class FixedPeriod(PlainPI):
    """Designed for 1 s only (takes no ``sample_period_s``)."""

    def __init__(self) -> None:
        super().__init__(1.0)


class TwoArgStep(PlainPI):
    def step(self, map_mmhg: float, target_mmhg: float) -> float:  # type: ignore[override]
        return 0.0


class HugeMax(PlainPI):
    def __init__(self, sample_period_s: float = 0.1) -> None:
        super().__init__(sample_period_s, max_rate_ml_h=1e9)


class FailsAt(PlainPI):
    """The plain PI until its ``at``-th step, which raises (``how="raise"``), returns NaN
    (``"nan"``) or returns ``None`` (``"none"``, a value ``float()`` refuses); every later step
    fails too unless ``once``."""

    def __init__(
        self, sample_period_s: float = 0.1, at: int = 50, how: str = "raise", once: bool = False
    ) -> None:
        super().__init__(sample_period_s, kp=2.0, ki=0.02)
        self.at, self.how, self.once, self.n = at, how, once, 0

    def step(self, map_mmhg: float, target_mmhg: float, K: float, T: float, tau: float) -> float:
        self.n += 1
        if self.n < self.at or (self.once and self.n > self.at):
            return super().step(map_mmhg, target_mmhg, K, T, tau)
        if self.how == "raise":
            raise ZeroDivisionError("plugin bug")
        return float("nan") if self.how == "nan" else None  # type: ignore[return-value]


class InternalError(BaseException):
    """Not an ``Exception``: what no handler of the controller's faults catches (a bug of the
    runtime itself, as far as the loop can tell)."""


class Crashes(PlainPI):
    """Raises :class:`InternalError` at its ``at``-th step: the runtime's loop dies from within."""

    def __init__(self, sample_period_s: float = 0.1, at: int = 20) -> None:
        super().__init__(sample_period_s)
        self.at, self.n = at, 0

    def step(self, map_mmhg: float, target_mmhg: float, K: float, T: float, tau: float) -> float:
        self.n += 1
        if self.n >= self.at:
            raise InternalError("the loop died")
        return super().step(map_mmhg, target_mmhg, K, T, tau)
