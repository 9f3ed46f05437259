"""Scheduling sources: where the controller's K, T, τ come from, one tick at a time.

Every source has the same method, ``update(inputs: ScheduleInput) -> Schedule``: the tick's
:class:`ScheduleInput` (MAP sample, quality bits, delivered rate and whatever scheduling parameters
the device sent) in, the tick's :class:`Schedule` out. Units and ranges of the result:
K > 0 mmHg/(ml/h), T > 0 s, τ ≥ 0 s (the controller clamps to its design box, as it always has).

This module holds the protocol and the two sources that learn nothing; the learning ones live in
:mod:`pressor.runtime.estimation` (which builds on :class:`Schedule`), and
:func:`pressor.runtime.estimation.sources.make_schedule` picks one by name.

:class:`OracleSchedule`
    The device's values, exactly as sent (a simulator's truth; research comparisons only).
    ``valid`` is False when the device sent none, flagged them invalid or sent non-finite values
    (NaN when it sent none); the supervisor and the controller's own invalid-input handling then
    apply, exactly as before this module existed.
:class:`NominalSchedule`
    Constant prior values (default: the nominal patient, :data:`NOMINAL_PLANT`); always valid.
:class:`pressor.runtime.estimation.sources.EstimatedSchedule`
    The online estimator, scheduled cautiously (see its docstring).
:class:`pressor.runtime.estimation.validated.ValidatedSchedule`
    Opt-in (``--schedule validated``): the nominal patient, with T and τ slewed inside the
    certified rates toward a model validated on held-out windows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, Protocol

from pressor.baselines.smith import INITIAL_SCHEDULE
from pressor.contracts.checks import check_range
from pressor.runtime.core.estimate import Estimate

#: the nominal patient (K mmHg/(ml/h), T s, τ s): the same constants as the estimator's prior
#: (:data:`pressor.runtime.estimation.settings.NOMINAL_PLANT`), named here so that the core needs no
#: estimation import
NOMINAL_PLANT: tuple[float, float, float] = INITIAL_SCHEDULE


class ScheduleInput(NamedTuple):
    """What a scheduling source is given at one tick (immutable; a named tuple for the per-tick
    cost).

    Attributes
    ----------
    map_mmhg
        The tick's MAP sample (mmHg); NaN when there is none or it is too old to use.
    quality
        Monitor quality bits (0 = good; :data:`pressor.contracts.faults` sensor-quality bits).
    delivered_ml_h
        The pump's latest delivered rate (ml/h, from PUMP_STATUS; 0 before any status).
    device_K
        Sensitivity the device sent (mmHg/(ml/h)); NaN when it sent none.
    device_T_s
        Lag the device sent (s); NaN when it sent none.
    device_tau_s
        Delay the device sent (s); NaN when it sent none.
    device_valid
        The device flagged its scheduling parameters valid (False when it sent none).
    target_mmhg
        The clinician's target MAP this tick (mmHg); NaN when the caller does not give it (the
        cautious source's dose ceiling and floor after the start then stay off).
    """

    map_mmhg: float
    quality: int
    delivered_ml_h: float
    device_K: float
    device_T_s: float
    device_tau_s: float
    device_valid: bool
    target_mmhg: float = math.nan


@dataclass(frozen=True, slots=True)
class Schedule:
    """The scheduling parameters of one tick.

    Attributes
    ----------
    K, T_s, tau_s
        Sensitivity (mmHg/(ml/h)), lag (s), delay (s); NaN only from an oracle without values.
    source
        ``"oracle"``, ``"estimated"``, ``"nominal"`` or ``"validated"``.
    valid
        Whether K, T, τ are usable (finite, positive).
    healthy
        False when the estimator's health check rejected its latest estimate (always True for the
        other sources).
    from_prior
        True when the values are the prior's (the nominal source, or the estimator learning or
        falling back).
    reason
        ``"ok"``, or why the values are not a fresh estimate (``"learning"``, ``"diverged"``,
        ``"K implausible"``, ``"T implausible"``, ``"no device values"``, ``"prior"``).
    estimate
        The estimator's full report (uncertainty, confidence, design-box flag); None for the
        other sources.
    """

    K: float
    T_s: float
    tau_s: float
    source: str
    valid: bool
    healthy: bool
    from_prior: bool
    reason: str
    estimate: Estimate | None = None


class ScheduleSource(Protocol):
    """What the closed-loop core (:mod:`pressor.runtime.core.closed_loop`) calls once per tick."""

    source: str

    def update(self, inputs: ScheduleInput) -> Schedule:
        """The tick's scheduling parameters (see the module docstring)."""
        ...


class OracleSchedule:
    """Schedule on the device's K, T, τ (the simulator's truth), passed through as sent."""

    source = "oracle"

    def update(self, inputs: ScheduleInput) -> Schedule:
        """The device's values as sent; ``valid`` only if finite and flagged valid."""
        K, T_s, tau_s = inputs.device_K, inputs.device_T_s, inputs.device_tau_s
        ok = inputs.device_valid and math.isfinite(K + T_s + tau_s)
        return Schedule(K, T_s, tau_s, "oracle", ok, True, False,
                        "ok" if ok else "no device values")  # fmt: skip


class NominalSchedule:
    """Schedule on constant values (a fixed-gain controller at that point).

    Parameters
    ----------
    K, T_s, tau_s
        Sensitivity (mmHg/(ml/h)) > 0, lag (s) > 0, delay (s) >= 0; default the nominal patient.
    """

    source = "nominal"

    def __init__(
        self,
        K: float = NOMINAL_PLANT[0],
        T_s: float = NOMINAL_PLANT[1],
        tau_s: float = NOMINAL_PLANT[2],
    ) -> None:
        K = check_range("K", K, 0.0, lo_open=True, unit="mmHg/(ml/h)")
        T_s = check_range("T_s", T_s, 0.0, lo_open=True, unit="s")
        tau_s = check_range("tau_s", tau_s, 0.0, unit="s")
        self._schedule = Schedule(K, T_s, tau_s, "nominal", True, True, True, "prior")

    def update(self, inputs: ScheduleInput) -> Schedule:
        """The constant values (the same object every tick)."""
        return self._schedule
