"""The supervisor's flatline rules: a frozen or damped arterial line, judged on new samples only.

A real monitor reports quantized MAP (integer mmHg is common) at about 1 Hz, and a steady patient
on it legitimately repeats values; a frozen transducer or monitor repeats its value for ever, and an
over-damped line smooths away the beat-to-beat variation. Both rules below see only *new* samples
(sample age 0: not a ``QUALITY_HELD`` repeat, not a tick without a sample), are off when the
monitor announces no noise (a noise-free simulator legitimately repeats values; the announced noise
must not exceed the true one), and scale with the announced noise σ and the monitor's quantum q:

``stuck``
    ``n`` consecutive new samples within ±h of the first, h = max(``eps_mmhg``, q/2), for at least
    ``min_s``. A sample of an honest monitor with noise σ falls within ±h of a given value with
    probability at most p = erf(h / (σ√2)), so ``n`` = ⌈ln α / ln p⌉ + 1 new samples make a false
    alarm less likely than α (:func:`stuck_samples`; α = 1e-9 per new sample: 1 h of a 1 Hz monitor
    gives ~4e-6). At σ = 1 mmHg, q = 1 mmHg: p ≤ 0.38, n = 23 samples (23 s at 1 Hz); σ = 0.1 mmHg
    continuous at 10 Hz: n = 23, so the ``min_s`` floor (10 s) decides, as before.
``damped``
    variance collapse: the mean squared successive difference of the last ``window`` new samples
    (and at least ``min_s`` of them) below 2 (``ratio`` σ)² (honest white noise gives 2σ², a slow
    trend adds little). Only when σ ≥ q: below that, quantization alone can make readings constant.
    At σ = 1 mmHg, q = 1 mmHg, 30 steps: a false alarm needs 27 of them to be zero, p < 1e-11.

The quantum is read off the values: the coarsest of :data:`GRAINS_MMHG` (1 mmHg down to 0.01 mmHg)
that every new sample so far is a multiple of, 0 for a monitor that reads finer (a float32 reading
of a continuous value is no multiple of any). So the first sample of an integer-mmHg monitor sets
q = 1 mmHg and a line frozen from the very start is caught too. A disconnected line (transducer
open to air, ~0 mmHg) is the supervisor's range check, same tick; the monitor's own waveform check
(``QUALITY_WAVEFORM``) is its quality check, same tick.
"""

from __future__ import annotations

import math
from collections import deque

#: false-alarm probability per new sample the stuck rule is sized for
FALSE_ALARM = 1e-9
#: the resolutions (mmHg) a monitor's readings are checked against, coarsest first
GRAINS_MMHG = (1.0, 0.5, 0.25, 0.2, 0.1, 0.05, 0.02, 0.01)


def grain_mmhg(map_mmhg: float) -> float:
    """The coarsest of :data:`GRAINS_MMHG` that ``map_mmhg`` is a multiple of (to 1e-4 of it, a
    float32 reading), else 0."""
    for g in GRAINS_MMHG:
        x = map_mmhg / g
        if abs(x - round(x)) <= 1e-4:
            return g
    return 0.0


def stuck_samples(noise_mmhg: float, quantum_mmhg: float, eps_mmhg: float) -> float:
    """New samples (count) the stuck rule needs for a false alarm below :data:`FALSE_ALARM`.

    Parameters
    ----------
    noise_mmhg
        The monitor's announced noise σ (mmHg), > 0.
    quantum_mmhg
        The monitor's quantum q (mmHg), >= 0.
    eps_mmhg
        The smallest half-width h (mmHg) of the stuck band; h = max(eps, q/2).

    Returns
    -------
    float
        ⌈ln α / ln p⌉ + 1 with p = erf(h / (σ√2)); ``inf`` when p rounds to 1 (σ far below h: a
        steady reading is expected, the rule cannot tell).
    """
    p = math.erf(max(eps_mmhg, 0.5 * quantum_mmhg) / (noise_mmhg * math.sqrt(2.0)))
    if p >= 1.0:
        return math.inf
    if p <= 0.0:
        return 2.0
    return float(math.ceil(math.log(FALSE_ALARM) / math.log(p)) + 1)


class FlatlineRules:
    """State of the two rules for one run; :meth:`update` is called with each new sample.

    Parameters
    ----------
    noise_mmhg
        The announced noise σ (mmHg), > 0.
    min_s
        Shortest flatline (s) either rule reports.
    eps_mmhg
        Smallest half-width of the stuck band (mmHg).
    window
        New samples (at least) the damped rule averages over.
    ratio
        The damped rule's threshold, as a fraction of σ.

    Attributes
    ----------
    quantum_mmhg
        The monitor's quantum as read off its values so far (mmHg; 0: finer than 0.01 mmHg).
    """

    def __init__(
        self, noise_mmhg: float, min_s: float, eps_mmhg: float, window: int, ratio: float
    ) -> None:
        self.noise_mmhg = noise_mmhg
        self.min_s = min_s
        self.eps_mmhg = eps_mmhg
        self.window = window
        self.quantum_mmhg = GRAINS_MMHG[0]
        self._collapse = 2.0 * (ratio * noise_mmhg) ** 2  # mmHg², on the mean squared step
        self._need = stuck_samples(noise_mmhg, self.quantum_mmhg, eps_mmhg)
        self._prev = math.nan
        self._anchor = math.nan
        self._anchor_s = 0.0
        self._run = 0
        self._steps: deque[tuple[float, float]] = deque()  # (time s, squared step mmHg²)
        self._sum = 0.0

    def update(self, now_s: float, map_mmhg: float) -> bool:
        """Take a new, plausible sample (mmHg) at ``now_s`` (s); return whether a rule fires."""
        prev = self._prev
        self._prev = map_mmhg
        if self.quantum_mmhg > 0.0:  # a quantum only ever gets finer
            grain = grain_mmhg(map_mmhg)
            if grain < self.quantum_mmhg:
                self.quantum_mmhg = grain
                self._need = stuck_samples(self.noise_mmhg, grain, self.eps_mmhg)
        anchor = self._anchor
        if abs(map_mmhg - anchor) > self.eps_mmhg or anchor != anchor:
            self._anchor = map_mmhg
            self._anchor_s = now_s
            self._run = run = 1
        else:
            self._run = run = self._run + 1
        min_s = self.min_s - 1e-9  # the same bound, computed once a sample (runs every tick)
        stuck = run >= self._need and now_s - self._anchor_s >= min_s
        if prev != prev:
            return stuck
        step = abs(map_mmhg - prev)
        step2 = step * step
        steps = self._steps
        steps.append((now_s, step2))
        total = self._sum + step2
        window = self.window
        while len(steps) > window and now_s - steps[1][0] >= min_s:
            total -= steps.popleft()[1]
        self._sum = total
        n = len(steps)
        damped = (
            n >= window
            and now_s - steps[0][0] >= min_s
            and self.noise_mmhg >= self.quantum_mmhg
            and total < self._collapse * n
        )
        return stuck or damped
