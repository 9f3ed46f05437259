"""The cautious start: schedule on the most sensitive patient, and let evidence lower K.

The premise (issue 41): the bedside knows the MAP, the delivered rate, the drug, the syringe, the
weight and the target from the first second, nothing more, so the first doses are blind. This
source makes them safe by construction and lets the MAP's response buy speed. Every choice below
was made on cohort seed 3 and judged on seed 2026; the figures, the variants tried and the
frontier are in docs/notes/cautious-start.md (the section named in each item).

* **Start at the top.** K̂ starts at the top of the design's patient population
  (``POPULATION_K_UG_KG_MIN``, mmHg per µg/kg/min, converted once to ml/h of the syringe and
  patient at hand, :class:`pressor.contracts.drug.DoseScale`), times the drug's start margin
  (:data:`CAUTION_FOR_DRUG`), inside the box. The controller's gains are 1/K̂ (the feedback's and
  the feedforward's: the generated module's prefilter runs on the feedback's own, rate-limited K),
  so the first commands are what the most sensitive patient of the range needs, and no more: on
  that patient they land on the target; on any other they fall short.
* **Lower K only on evidence.** Let ``s_slow(t)`` be the response of a unit-gain patient with the
  evidence's slowest lag and the box's longest delay (the box's T_hi unless the drug names a
  shorter ``evidence_T_s``; τ_hi; behind them the drug's effect site, if it names one) to the
  rate the pump delivered, and ``Δy`` the MAP's change since the first sample. Any first-order
  patient of the box with sensitivity K and a lag up to that one has risen at least
  ``K s_slow`` by now, so when ``Δy < K̂ s_slow − m`` the patient is less sensitive than K̂, at
  most ``K_up = (Δy + m)/s_slow``; K̂ falls toward K_up. No response after the longest delay is
  such evidence. The margin ``m = margin_mmhg + margin_rel K̂ s_slow`` covers the monitor's noise
  and a patient slower than the box. It needs no fit: an online fit from the first minute reads
  K/T, not K and T apart, and landed up to 2x low ("The mechanism").
* **Raise K on the contrary evidence.** When ``Δy > K̂ s_fast + m`` (s_fast: the fastest patient
  of the box, T_lo, τ_lo) the patient is more sensitive than K̂, at least ``(Δy − m)/s_fast``; K̂
  rises toward it (a higher K̂ is the cautious direction).
* **Not after a cut.** The bound rests on an ordering: a patient faster than the slowest has
  answered at least as much as it, which holds while the rate has not been cut. After a cut the
  low half of an oscillation would read as a less sensitive patient, so K̂ falls only while
  ``s_fast >= s_slow`` ("Steep patients").
* **A dose ceiling** (:attr:`Caution.hill_ceiling`, norepinephrine's). On a Hill curve that starts
  from zero the first doses answer almost nothing, and the bound above would lower K̂ to that
  low-dose gain. For Hill exponents up to n, E(c)/cⁿ does not grow with the concentration, and the
  effect site of a patient no slower than the evidence's slowest holds at least s_slow, so
  E(u) <= (Δy + m)(u/s_slow)ⁿ (m the evidence's ``margin_mmhg``). The dose that could lift the MAP
  past the step (target − first MAP) and :data:`CEILING_ALLOWANCE` of it is u_c
  (:func:`dose_ceiling_ml_h`), and a falling K̂ stops at step/u_c, where the law's steady dose
  reaches it. It never raises K̂ and needs the target
  (:attr:`~pressor.runtime.core.scheduling.ScheduleInput.target_mmhg`). It acts through K̂, a pace
  the law's transient may pass, because held as a cap on the command it starves every patient
  ("Steep patients").
* **After the start** (:attr:`Caution.settle_floor`, norepinephrine's). Once the MAP, having begun
  more than :data:`SETTLE_BAND_MMHG` below the target, first comes within it, K̂ no longer falls
  below that fraction of its value then: a disturbance that lowers the MAP afterwards (a
  haemorrhage, while the law raises the rate) would otherwise read as a less sensitive patient,
  and the loop, scheduled too low, oscillates ("Steep patients").
* **A swing raises K** (:attr:`Caution.swing_raise`, both drugs'). After the start, a MAP (read
  through a :data:`SWING_FILTER_S` low-pass, so that a monitor's noise is no swing) that leaves
  the band above the target after it last left it below has been driven past the target
  by the loop: K̂ is below the patient's gain there (a steep dose-response curve's local gain is up
  to n times its average, and a haemorrhage read as a less sensitive patient pulls K̂ down
  further). Each such swing raises K̂'s floor to 1.5 times K̂, never above K̂ when the start
  ended, and K̂ climbs to it at the certified rise: the loop gets gentler while it swings, and
  the evidence may not take that back ("Steep patients").
* **At the certified rates.** K̂ falls at most at the design's certified fall of ln K and rises at
  most at its certified rise (``RATE_BOUNDS[0]`` / ``K_RATE_UP_PER_S`` of a log-K design, times
  ``rate_fraction``), inside its box; τ is fixed at the box's longest, T at the drug's
  (:data:`CAUTION_FOR_DRUG`; by default the box's geometric mean). The design's certificate covers
  these rates (falls fast, rises slowly: a falling K is the benign direction,
  :mod:`pressor.synthesis.certificates.wirtinger.k_scaling`), and its module's bumpless integral
  keeps the command continuous while K̂ moves (:mod:`pressor.synthesis.families.smith.law`).

Each drug's settings, and why they are what they are, with :class:`Caution`,
:data:`CAUTION_FOR_DRUG`, the constants named here and :func:`dose_ceiling_ml_h`:
:mod:`pressor.runtime.estimation.caution`.

What is not covered. The evidence assumes the drug's effect rises with the dose (a vasopressor).
The certificate covers K̂ = K, not K̂ ≠ K, and the construction bounds the first commands, not the
closed loop's overshoot on every first-order patient of the box ("The box's slow corner").
Phenylephrine has neither ceiling nor floor, and on dose-response curves from zero much steeper
than its patient models its steps overshoot; norepinephrine's still do on patients whose delay is
beyond its box ("Norepinephrine over the link, on a second model").
"""

from __future__ import annotations

import math
from collections.abc import Callable

from pressor.contracts.drug import REFERENCE_WEIGHT_KG, DoseScale
from pressor.runtime.core.scheduling import Schedule, ScheduleInput
from pressor.runtime.estimation.caution import (
    CAUTION_FOR_DRUG,
    SETTLE_BAND_MMHG,
    SWING_FILTER_S,
    Caution,
    dose_ceiling_ml_h,
)
from pressor.runtime.estimation.design_envelope import DesignEnvelope
from pressor.runtime.estimation.gate import SampleGate
from pressor.runtime.estimation.unit_lag import UnitLag

__all__ = ["CautiousSchedule"]


def _rule_setting(
    name: str, given: float | None, drug: float | None, ok: Callable[[float], bool], allowed: str
) -> float | None:
    """An optional rule's setting: ``given`` (0 turns the rule off), else the ``drug``'s; None
    when off. A finite value that fails ``ok`` is a :class:`ValueError` naming it and
    ``allowed``."""
    value = drug if given is None else float(given)
    if value is None or value == 0.0:
        return None
    if not (math.isfinite(value) and ok(value)):
        raise ValueError(f"{name}={value!r} must be {allowed} (0: none)")
    return value


class CautiousSchedule:
    """Schedule K̂ from the population's top down, on evidence (module docstring).

    Parameters
    ----------
    envelope
        The design's box, certified ln K rates, population and syringe
        (:func:`pressor.runtime.estimation.design_envelope.envelope_of`).
    sample_period_s
        Tick period (s), > 0.
    dose
        The syringe and patient (default: the design's syringe and the reference adult,
        :data:`pressor.contracts.drug.REFERENCE_WEIGHT_KG`, as the simulated patients are): converts the
        population's doses to ml/h once.
    margin_mmhg, margin_rel
        The evidence margin m = margin_mmhg + margin_rel × (the response K̂ predicts), mmHg and 1,
        each >= 0.
    rate_fraction
        Share of the certified ln K rates the source moves at, in (0, 1] (the module limits to the
        full rates; 1 % short of them keeps its limiter idle whatever the rounding).
    T_s, tau_s
        The lag (s) and delay (s) to schedule on; default the drug's T
        (:data:`CAUTION_FOR_DRUG`, else the box's geometric mean) and the box's longest τ (module
        docstring).
    start_margin
        K̂ starts at this multiple of the population's top, >= 1, clamped to the box; default the
        drug's (:data:`CAUTION_FOR_DRUG`, else 1).
    evidence_T_s
        The lag (s) of the evidence's slowest patient, inside the design's T box; default the
        drug's (:data:`CAUTION_FOR_DRUG`), else the box's longest.
    hill_ceiling
        The dose ceiling's Hill exponent n, >= 1 (module docstring, "A dose ceiling"); default
        the drug's (:data:`CAUTION_FOR_DRUG`); 0 turns a drug's ceiling off. It acts only on the
        ticks that give the target (:attr:`ScheduleInput.target_mmhg`).
    settle_floor
        K̂'s floor after the start, a fraction in (0, 1] of K̂ when the MAP first came within
        :data:`SETTLE_BAND_MMHG` of the target (module docstring, "After the start"); default
        the drug's (:data:`CAUTION_FOR_DRUG`); 0 turns it off. It needs the target too.
    swing_raise
        The factor (> 1) a swing up through the band raises K̂'s floor to, over K̂ then (module
        docstring, "A swing raises K"); default the drug's (:data:`CAUTION_FOR_DRUG`); 0 turns it
        off. It needs the target too.

    The sample gate (:class:`pressor.runtime.estimation.gate.SampleGate`) keeps bad samples out of the
    evidence, but not a MAP that does not move: here no movement is the evidence (a frozen
    transducer is the supervisor's to catch, by its flatline rules).
    """

    source = "cautious"

    def __init__(
        self,
        envelope: DesignEnvelope,
        sample_period_s: float = 0.1,
        dose: DoseScale | None = None,
        margin_mmhg: float = 1.0,
        margin_rel: float = 0.1,
        rate_fraction: float = 0.99,
        T_s: float | None = None,
        tau_s: float | None = None,
        start_margin: float | None = None,
        evidence_T_s: float | None = None,
        hill_ceiling: float | None = None,
        settle_floor: float | None = None,
        swing_raise: float | None = None,
    ) -> None:
        if not (math.isfinite(sample_period_s) and sample_period_s > 0.0):
            raise ValueError(f"sample_period_s={sample_period_s!r} must be finite and > 0")
        for name, value in (("margin_mmhg", margin_mmhg), ("margin_rel", margin_rel)):
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name}={value!r} must be finite and >= 0")
        if not 0.0 < rate_fraction <= 1.0:
            raise ValueError(f"rate_fraction={rate_fraction!r} must be in (0, 1]")
        self.envelope = env = envelope
        caution = CAUTION_FOR_DRUG.get(env.drug, Caution())
        margin = caution.start_margin if start_margin is None else float(start_margin)
        if not (math.isfinite(margin) and margin >= 1.0):
            raise ValueError(f"start_margin={start_margin!r} must be finite and >= 1")
        self.dose = dose or DoseScale(env.concentration_ug_ml, REFERENCE_WEIGHT_KG)
        (k_lo, k_hi), (t_lo, t_hi), (d_lo, d_hi) = env.box
        top = self.dose.k_ml_h(env.population[1])
        self.k_top = min(max(margin * top, k_lo), k_hi)
        self.k_floor = min(max(self.dose.k_ml_h(env.population[0]), k_lo), self.k_top)
        T_s = caution.T_s if T_s is None else T_s
        self.T_s = math.sqrt(t_lo * t_hi) if T_s is None else float(T_s)
        if not t_lo <= self.T_s <= t_hi:
            raise ValueError(
                f"T_s={self.T_s!r} s must lie in the design's T box [{t_lo}, {t_hi}] s"
            )
        self.tau_s = d_hi if tau_s is None else float(tau_s)
        slowest = caution.evidence_T_s if evidence_T_s is None else evidence_T_s
        self.evidence_T_s = t_hi if slowest is None else float(slowest)
        if not t_lo <= self.evidence_T_s <= t_hi:
            raise ValueError(
                f"evidence_T_s={self.evidence_T_s!r} s must lie in the design's T box"
                f" [{t_lo}, {t_hi}] s"
            )
        ts = float(sample_period_s)
        self._down = math.exp(-rate_fraction * env.fall_per_s * ts)
        self._up = math.exp(rate_fraction * env.rise_per_s * ts)
        self._m, self._rel = float(margin_mmhg), float(margin_rel)
        self._hist = [0.0] * (int(math.ceil(d_hi / ts)) + 3)
        self._head = 0
        lag2 = caution.effect_lag_s
        if lag2 is not None and not (math.isfinite(lag2) and lag2 > 0.0):
            raise ValueError(f"effect_lag_s={lag2!r} must be finite and > 0 (s)")
        self.effect_lag_s = lag2
        self.hill_ceiling = n = _rule_setting(
            "hill_ceiling",
            hill_ceiling,
            caution.hill_ceiling,
            lambda v: v >= 1.0,
            "finite and >= 1",
        )
        self._inv_n = 0.0 if n is None else 1.0 / n
        self.settle_floor = _rule_setting(
            "settle_floor",
            settle_floor,
            caution.settle_floor,
            lambda v: 0.0 < v <= 1.0,
            "in (0, 1]",
        )
        self.swing_raise = _rule_setting(
            "swing_raise", swing_raise, caution.swing_raise, lambda v: v > 1.0, "finite and > 1"
        )
        self._k_settled = 0.0  # K̂'s floor once the start has ended (0 before, or without one)
        # the start has not ended yet (tracked only for a rule that acts after it)
        self._settling = self.settle_floor is not None or self.swing_raise is not None
        self._k_entry = 0.0  # K̂ when the start ended
        self._side = 0  # the side of the band the MAP last left it on after the start (+1, -1)
        self._y_slow = 0.0  # the MAP's low-pass (SWING_FILTER_S) after the start (mmHg)
        self._a_slow = math.exp(-ts / SWING_FILTER_S)
        self._slow = UnitLag(self.evidence_T_s, d_hi, ts, lag2)
        self._fast = UnitLag(t_lo, d_lo, ts)
        self._gate = SampleGate(ts, flatline_s=1e9)  # no flatline rule (class docstring)
        self._anchor: float | None = None
        self.K = self.k_top
        self._schedule = Schedule(self.K, self.T_s, self.tau_s, "cautious", True, True, True,
                                  "prior")  # fmt: skip

    def update(self, inputs: ScheduleInput) -> Schedule:
        """Feed one tick (the delivered rate, the MAP sample) and schedule on K̂."""
        u = inputs.delivered_ml_h
        hist = self._hist
        head = self._head
        hist[head] = u if u == u and u >= 0.0 else 0.0
        self._head = head = (head + 1) % len(hist)
        s_slow = self._slow.step(hist, head)
        s_fast = self._fast.step(hist, head)
        y = inputs.map_mmhg
        if not self._gate.accept(y, inputs.quality):
            return self._schedule
        if self._anchor is None:
            self._anchor = y
            return self._schedule
        dy = y - self._anchor
        k = self.K
        pred = k * s_slow
        m = self._m + self._rel * pred
        if s_slow > 0.0 and dy < pred - m:  # less response than the slowest K̂ patient
            if s_fast >= s_slow:  # ... evidence only while the rate has not been cut (docstring)
                k = max(k * self._down, (dy + m) / s_slow, self.k_floor)
                if self._inv_n:
                    k = self._under_the_ceiling(k, dy, s_slow, inputs.target_mmhg)
        else:
            pred_f = k * s_fast
            m_f = self._m + self._rel * pred_f
            if s_fast > 0.0 and dy > pred_f + m_f:  # more than the fastest K̂ patient could give
                k = min(k * self._up, (dy - m_f) / s_fast, self.k_top)
        if k < self._k_settled:  # the floor after the start: held, or climbed to at the certified
            k = max(k, min(self.K * self._up, self._k_settled))  # rise once a swing raised it
        if k != self.K:
            self.K = k
            self._schedule = Schedule(k, self.T_s, self.tau_s, "cautious", True, True, False,
                                      "evidence")  # fmt: skip
        target = inputs.target_mmhg
        band = SETTLE_BAND_MMHG
        if self._settling:
            if abs(y - target) <= band and self._anchor < target - band:
                self._settling = False  # the MAP has risen into the band: the start ends here
                self._k_settled = (self.settle_floor or 0.0) * k
                self._k_entry = k
                self._y_slow = y
        elif self.swing_raise is not None:
            self._y_slow = y_slow = y + self._a_slow * (self._y_slow - y)
            side = 1 if y_slow > target + band else -1 if y_slow < target - band else 0
            if side and side != self._side:
                if side > 0 and self._side < 0:  # out above after out below: a swing (docstring)
                    raised = min(self.swing_raise * k, self._k_entry)
                    self._k_settled = max(self._k_settled, raised)
                self._side = side
        return self._schedule

    def _under_the_ceiling(self, k: float, dy: float, s_slow: float, target_mmhg: float) -> float:
        """``k`` raised to step/u_c if it fell below it (no higher than K̂ was), u_c the dose
        ceiling of the module docstring; ``k`` itself without a target above the first MAP."""
        step = target_mmhg - self._anchor  # type: ignore[operator]
        if not step > 0.0:  # no target (NaN), or none above the first MAP: nothing to bound
            return k
        floor = step / dose_ceiling_ml_h(s_slow, step, dy, self._m, self._inv_n)
        return k if k >= floor else min(self.K, floor)
