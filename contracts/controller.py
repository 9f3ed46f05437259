"""The one small interface every controller the runtime can run implements.

Both the generated LPV modules (``codegen``) and the PI baseline (:mod:`pressor.baselines.pi`)
satisfy :class:`Controller`; the loop, the in-process simulator (``hil_sim``) and user code call
nothing else. A step is a pure function of the controller's own state and its arguments: no clock,
no I/O, no allocation that grows.

Optional, read by the recorder only: ``scheduled_rho() -> (K, T, tau)``, the scheduling values the
last step used after the controller's own clamp and rate limit (mmHg/(ml/h), s, s; NaN before the
first step). The Smith predictor has it; a generated LPV module exposes the same values as the last
three entries of its ``state()``.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from pressor.contracts.drug import DEFAULT_BINDING

#: The drug the shipped designs are for (the paper's vasopressor).
DESIGN_DRUG = DEFAULT_BINDING.name
#: The syringe concentration (µg/ml) the shipped designs' gain units assume. K is in mmHg/(ml/h),
#: so a design holds only at the concentration its K was identified at. The paper does not state
#: it; 100 µg/ml is the usual phenylephrine infusion dilution (10 mg in 100 ml), assumed here.
#: A generated module declares its own (``DRUG``, ``DRUG_CONCENTRATION_UG_ML``; read by
#: :func:`pressor.contracts.drug.binding_of`); the baselines declare none and assume these.
DESIGN_CONCENTRATION_UG_ML = DEFAULT_BINDING.concentration_ug_ml


@runtime_checkable
class ControllerStatus(Protocol):
    """Flags describing the last step.

    Attributes
    ----------
    saturated
        The command was clamped to [0, max_rate_ml_h] (anti-windup active).
    rho_clamped
        A scheduling parameter was outside the design box and was clamped to it.
    rho_rate_limited
        A scheduling parameter changed faster than the synthesis rate bound and was rate-limited.
    """

    saturated: bool
    rho_clamped: bool
    rho_rate_limited: bool


@runtime_checkable
class Controller(Protocol):
    """A discrete-time MAP controller stepped once per sample period.

    Attributes
    ----------
    sample_period_s
        The period (s) the controller was designed/discretised for; the loop must run at it.
    max_rate_ml_h
        Upper pump limit (ml/h); every command lies in [0, max_rate_ml_h].
    """

    sample_period_s: float
    max_rate_ml_h: float

    def step(self, map_mmhg: float, target_mmhg: float, K: float, T: float, tau: float) -> float:
        """Advance one sample period and return the infusion command (ml/h) for this tick.

        Parameters
        ----------
        map_mmhg
            Measured mean arterial pressure (mmHg).
        target_mmhg
            MAP target (mmHg).
        K, T, tau
            Scheduling parameters: sensitivity (mmHg/(ml/h)), lag (s), delay (s).
        """
        ...

    def reset(self) -> None:
        """Return to the initial state (zero infusion, empty delay line)."""
        ...

    @property
    def status(self) -> ControllerStatus:
        """Flags of the last step."""
        ...
