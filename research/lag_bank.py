"""Can the data tell the cautious start the patient's lag in time? A least-squares bank over (T, τ).

:mod:`research.evidence_lag` measures what knowing the lag would buy. This source tries to learn
it: a bank of first-order patients over the design box (``--lags`` T values, log-spaced, times
``--delays`` τ values, each behind the drug's effect site), each fitted to the MAP's rise since the
first sample by least squares on its gain. Once the rise passes ``--rise-mmhg``, a lag whose RMS
residual exceeds (1 + ``--rho``) × the best one's + ``--slack-mmhg`` is dropped for good, and the
evidence reads the slowest lag still in the bank (largest T + τ) in place of the box's slowest,
with the shipped rule and margins (:mod:`pressor.runtime.estimation.cautious`). From ``--after-s``
on only: 0 lets it act on the step, 900 only after the step (on the disturbances).

Usage (the table of :mod:`research.cautious_levels`, on this source)::

    python -m research.lag_bank --controller lpv:norepinephrine-cautious \\
        --patient-model norepinephrine --levels 0.5,1,2,10 --patients 10 --seed 3

Measured in docs/notes/cautious-start.md, "What knowing the lag would buy".
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass

from pressor.contracts.drug import DoseScale
from pressor.runtime.core.scheduling import Schedule, ScheduleInput
from pressor.runtime.estimation.cautious import CautiousSchedule
from pressor.runtime.estimation.design_envelope import DesignEnvelope
from pressor.runtime.estimation.unit_lag import UnitLag
from research import cautious_levels


@dataclass(frozen=True)
class BankSettings:
    """The bank's grid and its test (module docstring; units in the names)."""

    lags: int = 6
    delays: int = 4
    rho: float = 0.5
    slack_mmhg: float = 0.2
    rise_mmhg: float = 3.0
    after_s: float = 0.0
    every_ticks: int = 10


class _Chosen:
    """Stands in for the cautious source's slowest patient: the chosen bank member's response."""

    __slots__ = ("value",)

    def __init__(self) -> None:
        self.value = 0.0

    def step(self, hist: list[float], head: int) -> float:
        return self.value


class LagBankSchedule(CautiousSchedule):
    """:class:`~pressor.runtime.estimation.cautious.CautiousSchedule` whose slowest patient is the
    slowest lag of a least-squares bank the data still fit (module docstring)."""

    def __init__(
        self,
        envelope: DesignEnvelope,
        sample_period_s: float = 0.1,
        dose: DoseScale | None = None,
        settings: BankSettings = BankSettings(),
    ) -> None:
        super().__init__(envelope, sample_period_s, dose)
        _, (t_lo, t_hi), (d_lo, d_hi) = envelope.box
        n_t, n_d = settings.lags, settings.delays
        lags = [t_lo * (t_hi / t_lo) ** (i / (n_t - 1)) for i in range(n_t)]
        delays = [d_lo + (d_hi - d_lo) * i / (n_d - 1) for i in range(n_d)]
        self.hypotheses = [(T, d) for T in lags for d in delays]
        self._bank = [UnitLag(T, d, sample_period_s, self.effect_lag_s) for T, d in self.hypotheses]
        n = len(self.hypotheses)
        self._slowest_first = sorted(range(n), key=lambda j: -sum(self.hypotheses[j]))
        self._sxy, self._sxx = [0.0] * n, [0.0] * n
        self._syy, self._n = 0.0, 0
        self.alive = [True] * n
        self.chosen = self._slowest_first[0]
        self.drops: list[tuple[float, tuple[float, float]]] = []  # (s, the lag then read)
        self._set = settings
        self._ts = float(sample_period_s)
        self._tick = 0
        self._slow = self._proxy = _Chosen()

    def update(self, inputs: ScheduleInput) -> Schedule:
        """Step the bank on this tick's rate, refit, then the cautious source's tick."""
        u = inputs.delivered_ml_h
        hist, head = self._hist, self._head
        hist[head] = u if u == u and u >= 0.0 else 0.0  # what the source writes there this tick
        nxt = (head + 1) % len(hist)
        s = [b.step(hist, nxt) for b in self._bank]
        self._tick += 1
        y = inputs.map_mmhg
        if self._anchor is not None and y == y:
            self._fit(s, y - self._anchor)
        self._proxy.value = s[self.chosen]
        return super().update(inputs)

    def _fit(self, s: list[float], dy: float) -> None:
        st = self._set
        self._n += 1
        self._syy += dy * dy
        for j, sj in enumerate(s):
            self._sxy[j] += sj * dy
            self._sxx[j] += sj * sj
        now_s = self._tick * self._ts
        if dy <= st.rise_mmhg or now_s < st.after_s or self._tick % st.every_ticks:
            return
        rms = []
        for j in range(len(s)):
            k = self._sxy[j] / self._sxx[j] if self._sxx[j] > 0.0 else -1.0
            sse = self._syy - self._sxy[j] * k
            rms.append(math.sqrt(max(sse, 0.0) / self._n) if k > 0.0 else math.inf)
        best = min(rms)
        for j, r in enumerate(rms):
            if r > best * (1.0 + st.rho) + st.slack_mmhg:
                self.alive[j] = False
        for j in self._slowest_first:
            if self.alive[j]:
                if j != self.chosen:
                    self.chosen = j
                    self.drops.append((now_s, self.hypotheses[j]))
                return


def main(argv: list[str] | None = None) -> int:
    """The bank's settings here, every other argument :mod:`research.cautious_levels`'s."""
    d = BankSettings()
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0], add_help=False)
    p.add_argument("--lags", type=int, default=d.lags, help=f"T values (default {d.lags})")
    p.add_argument("--delays", type=int, default=d.delays, help=f"τ values (default {d.delays})")
    p.add_argument("--rho", type=float, default=d.rho, help=f"default {d.rho}")
    p.add_argument("--slack-mmhg", type=float, default=d.slack_mmhg, help=f"default {d.slack_mmhg}")
    p.add_argument("--rise-mmhg", type=float, default=d.rise_mmhg, help=f"default {d.rise_mmhg}")
    p.add_argument("--after-s", type=float, default=d.after_s, help=f"default {d.after_s}")
    a, rest = p.parse_known_args(argv)
    if a.lags < 2 or a.delays < 2:
        p.error(f"--lags {a.lags} and --delays {a.delays}: allowed 2 or more each")
    settings = BankSettings(a.lags, a.delays, a.rho, a.slack_mmhg, a.rise_mmhg, a.after_s)
    cautious_levels.use_cautious_source(LagBankSchedule, settings=settings)
    return cautious_levels.main(rest)


if __name__ == "__main__":
    sys.exit(main())
