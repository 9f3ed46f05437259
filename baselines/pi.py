"""The paper's PI baseline, Gc(s) = 3 + 0.017/s, as a discrete controller with anti-windup.

Standard library only. The error is e = target − MAP (mmHg); the command is in ml/h::

    u_k = clamp(Kp·e_k + I_k, 0, u_max)
    I_{k+1} = I_k + Ki·Ts·e_k        (skipped while saturated and e_k drives further into the limit)

Kp = 3 (ml/h)/mmHg and Ki = 0.017 (ml/h)/(mmHg·s) were tuned by the paper's authors for the nominal
plant K̄ = 0.55 mmHg/(ml/h), T̄ = 150 s, τ̄ = 40 s. The integrator is forward Euler at the sample
period, so at Ts = 0.1 s the loop matches the continuous PI to within a few hundredths of a mmHg.
Conditional integration is the anti-windup: the paper has none, but a real pump saturates.
The scheduling arguments (K, T, tau) are accepted for interface compatibility and ignored.
A non-finite MAP or target holds the previous command without integrating (the supervisor decides
what to do about the bad sample; the controller never returns NaN).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pressor.contracts.checks import check_range

KP_ML_H_PER_MMHG = 3.0
KI_ML_H_PER_MMHG_S = 0.017


def check_period_and_limit(sample_period_s: float, max_rate_ml_h: float) -> None:
    """Reject a sample period outside (0, 10] s or a pump limit outside (0, 10000] ml/h.

    Raises
    ------
    ValueError
        Naming the argument, its value and the allowed range.
    """
    check_range("sample_period_s", sample_period_s, 0.0, 10.0, lo_open=True, unit="s")
    check_range("max_rate_ml_h", max_rate_ml_h, 0.0, 10000.0, lo_open=True, unit="ml/h")


@dataclass
class PIStatus:
    """Flags of the last PI step (``rho_*`` are always False: the PI is not scheduled)."""

    saturated: bool = False
    rho_clamped: bool = False
    rho_rate_limited: bool = False


class PIController:
    """Discrete PI baseline implementing :class:`pressor.contracts.controller.Controller`.

    Parameters
    ----------
    sample_period_s
        Sample period Ts in s, in (0, 10].
    max_rate_ml_h
        Pump limit in ml/h, in (0, 10000].
    kp
        Proportional gain in (ml/h)/mmHg, ≥ 0.
    ki
        Integral gain in (ml/h)/(mmHg·s), ≥ 0.

    Bound to no drug (``DRUG_AGNOSTIC``, :func:`pressor.contracts.drug.drug_agnostic`): the gains are in
    ml/h for the nominal patient K ≈ 0.55 mmHg/(ml/h), which the usual syringes of every shipped
    drug share (docs/DRUGS.md), so ``pressor run`` runs it on the drug the clinician names.
    """

    DRUG_AGNOSTIC = True

    def __init__(
        self,
        sample_period_s: float = 0.1,
        max_rate_ml_h: float = 120.0,
        kp: float = KP_ML_H_PER_MMHG,
        ki: float = KI_ML_H_PER_MMHG_S,
    ) -> None:
        check_period_and_limit(sample_period_s, max_rate_ml_h)
        if kp < 0.0 or ki < 0.0:
            raise ValueError(f"PI gains must be >= 0, got kp={kp!r}, ki={ki!r}")
        self.sample_period_s = float(sample_period_s)
        self.max_rate_ml_h = float(max_rate_ml_h)
        self.kp = float(kp)
        self.ki = float(ki)
        self._integral_ml_h = 0.0
        self._last_command_ml_h = 0.0
        self._status = PIStatus()

    def reset(self) -> None:
        """Zero the integrator, the held command and the status flags."""
        self._integral_ml_h = 0.0
        self._last_command_ml_h = 0.0
        self._status = PIStatus()

    @property
    def status(self) -> PIStatus:
        """Flags of the last step."""
        return self._status

    def step(self, map_mmhg: float, target_mmhg: float, K: float, T: float, tau: float) -> float:
        """Return the infusion command (ml/h) for this tick; see the module docstring."""
        error_mmhg = target_mmhg - map_mmhg
        if not math.isfinite(error_mmhg):
            return self._last_command_ml_h
        unclamped = self.kp * error_mmhg + self._integral_ml_h
        command = min(max(unclamped, 0.0), self.max_rate_ml_h)
        saturated = command != unclamped
        winding_up = (unclamped > self.max_rate_ml_h and error_mmhg > 0.0) or (
            unclamped < 0.0 and error_mmhg < 0.0
        )
        if not winding_up:
            self._integral_ml_h += self.ki * self.sample_period_s * error_mmhg
        self._status = PIStatus(saturated=saturated)
        self._last_command_ml_h = command
        return command
