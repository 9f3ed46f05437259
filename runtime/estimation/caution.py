"""Each drug's caution for the cautious start, and the dose ceiling's formula.

What :class:`pressor.runtime.estimation.cautious.CautiousSchedule` (the cautious source) reads
per drug (the rules are stated in its module's docstring; the section names in quotes are in
docs/notes/cautious-start.md, where the figures behind each choice are):

* phenylephrine's PK/PD patients answer later than any first-order patient of the box and are
  less sensitive at low doses than near the target, so its evidence waits for a 60 s effect site
  behind the slowest patient, K̂ starts at twice the population's top, and the law runs on T 300 s
  (a weaker integral): together about 4 minutes to the target at 1x, for the overshoot bound
  ("Phenylephrine's evidence lag");
* norepinephrine's evidence reads a slowest patient of 550 s instead of the box's 750 s (K̂ had
  stopped up to twice a typical patient's gain: "Norepinephrine's evidence lag"); its design
  certifies a faster fall of ln K ("Norepinephrine's faster fall"); its dose ceiling (n = 2.5, a
  second model's steepest curves) and floor after the start (half) keep steep patients' steps
  and haemorrhages safe, and its law went back from T 250 s to 300 s because the ceiling's
  steep patients still overshot on the stronger integral. The issue ranks no hypertensive
  overshoot before time to the target: this costs the typical patient 4-7 minutes ("Steep
  patients", "Measured").
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "CAUTION_FOR_DRUG",
    "CEILING_ALLOWANCE",
    "SETTLE_BAND_MMHG",
    "SWING_FILTER_S",
    "Caution",
    "dose_ceiling_ml_h",
]


@dataclass(frozen=True)
class Caution:
    """How cautiously a drug's patients are started (module docstring).

    Attributes
    ----------
    start_margin
        K̂ starts at this multiple of the population's top (1, >= 1; clamped to the box).
    T_s
        The lag the law is scheduled on (s), inside the box; None: the box's geometric-mean T.
    effect_lag_s
        An effect site's lag (s, > 0) behind the evidence's slowest patient; None: none.
    evidence_T_s
        The lag (s) of the evidence's slowest patient, inside the box; None: the box's longest T.
    hill_ceiling
        The dose ceiling's Hill exponent n (>= 1; the cautious source's "A dose ceiling"); None: no
        ceiling.
    settle_floor
        Once the MAP has first come within :data:`SETTLE_BAND_MMHG` of the target, K̂ no longer
        falls below this fraction (0, 1] of its value then (the cautious
        source's "After the start");
        None: no such floor.
    swing_raise
        After the start, each swing of the MAP (low-passed, :data:`SWING_FILTER_S`) up through the
        band (it leaves the band above the target after it last left it below) raises K̂'s floor
        to this multiple (> 1) of K̂ then, never above K̂ when the start ended, and K̂ climbs to it
        at the certified rise (the cautious source's "A swing raises K"); None: no such rule.
    """

    start_margin: float = 1.0
    T_s: float | None = None
    effect_lag_s: float | None = None
    evidence_T_s: float | None = None
    hill_ceiling: float | None = None
    settle_floor: float | None = None
    swing_raise: float | None = None


#: the drug's caution (lower-case drug name -> :class:`Caution`); other drugs take ``Caution()``
CAUTION_FOR_DRUG: dict[str, Caution] = {
    "phenylephrine": Caution(start_margin=2.0, T_s=300.0, effect_lag_s=60.0, swing_raise=1.5),
    "norepinephrine": Caution(
        T_s=300.0, evidence_T_s=550.0, hill_ceiling=2.5, settle_floor=0.5, swing_raise=1.5
    ),
}
#: the rise above the step (a fraction of it) the dose ceiling lets a Hill curve reach: the
#: issue's overshoot bound (10 % of the step)
CEILING_ALLOWANCE = 0.1
#: the band around the target (mmHg) whose first entry ends the start (:attr:`Caution.settle_floor`)
#: and that a swing crosses (:attr:`Caution.swing_raise`)
SETTLE_BAND_MMHG = 5.0
#: the time constant (s) of the MAP's low-pass that a swing is read on
#: (:attr:`Caution.swing_raise`): a loop's swing lasts minutes, while a monitor's noise (2 mmHg at
#: 1 Hz raised K̂ on every patient unfiltered) and the breath's rhythm last seconds
SWING_FILTER_S = 30.0


def dose_ceiling_ml_h(
    s_ml_h: float,
    step_mmhg: float,
    dy_mmhg: float,
    margin_mmhg: float,
    inv_n: float,
    allowance: float = CEILING_ALLOWANCE,
) -> float:
    """u_c (ml/h): the steady dose past which a Hill curve from zero of exponent n = 1/``inv_n``
    could lift the MAP beyond ``(1 + allowance) step_mmhg``, given that a patient that has
    absorbed ``s_ml_h`` answered ``dy_mmhg`` (clipped at 0) within ``margin_mmhg`` (the
    cautious source's "A dose ceiling"): ``s (1.1 step/(Δy + m))^(1/n)``."""
    rise = (1.0 + allowance) * step_mmhg / ((dy_mmhg if dy_mmhg > 0.0 else 0.0) + margin_mmhg)
    return s_ml_h * rise**inv_n
