"""The paper's PI baseline Gc(s) = 3 + 0.017/s on the synthesis side (continuous time).

The gains are the runtime's (:mod:`pressor.baselines.pi`, the discrete PI with anti-windup that
the bedside loop runs); this module gives the same controller the continuous-time forms the
synthesis-side checks need:

- :meth:`PIBaseline.as_output_feedback` — the same PI written in the LPV controller's interface
  (a ``DelayedController``-shaped object on y = [e; x_e]: Dk = [kp, ki], no states of its own), so
  it can be closed with any plant model through :func:`pressor.synthesis.problem.closed_loop.close_loop`.
- :meth:`PIBaseline.step_loop` — the PI loop on the plain first-order-plus-delay plant
  K e^{-tau s}/(T s + 1) (no input filter: the filter Omega/(s+Lambda) belongs to the LPV design)
  for :func:`pressor.synthesis.verification.step_response.simulate_step`, i.e. the same step interface as
  the LPV loop.

With the nominal plant this reproduces the independent reference figures of docs/DESIGN-CHOICES.md
(overshoot 0 %, rise 109.5 s, settling 418.8 s).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from pressor.baselines.pi import KI_ML_H_PER_MMHG_S, KP_ML_H_PER_MMHG
from pressor.synthesis.problem.closed_loop import DelaySystem, OutputFeedback
from pressor.synthesis.verification.step_response import StepLoop

__all__ = ["PIBaseline"]


@dataclass(frozen=True)
class PIBaseline:
    """Gc(s) = kp + ki/s.

    Parameters
    ----------
    kp
        Proportional gain, (ml/h)/mmHg, >= 0 (paper: 3).
    ki
        Integral gain, (ml/h)/(mmHg*s), >= 0 (paper: 0.017).
    """

    kp: float = field(default=KP_ML_H_PER_MMHG)
    ki: float = field(default=KI_ML_H_PER_MMHG_S)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.kp) and np.isfinite(self.ki) and self.kp >= 0 and self.ki >= 0):
            raise ValueError(f"PI gains must be finite and >= 0, got kp={self.kp}, ki={self.ki}")

    def as_output_feedback(self) -> OutputFeedback:
        """The PI as a static feedback on y = [e (mmHg); x_e (mmHg*s)]: u = kp e + ki x_e."""
        return OutputFeedback(
            Ak=np.zeros((0, 0)),
            Adk=np.zeros((0, 0)),
            Bk=np.zeros((0, 2)),
            Ck=np.zeros((1, 0)),
            Cdk=np.zeros((1, 0)),
            Dk=np.array([[self.kp, self.ki]]),
        )

    def _loop_matrices(self, k: float, t_s: float) -> tuple[NDArray[np.float64], ...]:
        if not (k > 0 and t_s > 0 and np.isfinite(k) and np.isfinite(t_s)):
            raise ValueError(f"plant K={k!r} and T={t_s!r} must be finite and > 0")
        # state [dMAP (mmHg), x_e (mmHg*s)], u(t) = kp (r - dMAP) + ki x_e, plant sees u(t - tau)
        a = np.array([[-1.0 / t_s, 0.0], [-1.0, 0.0]])
        ad = (k / t_s) * np.array([[-self.kp, self.ki], [0.0, 0.0]])
        return a, ad

    def step_loop(self, k: float, t_s: float, tau_s: float) -> StepLoop:
        """The PI loop on K e^{-tau s}/(T s + 1) driven by the target r (mmHg).

        Parameters
        ----------
        k
            Sensitivity K, mmHg/(ml/h), > 0.
        t_s
            Lag T, s, > 0.
        tau_s
            Delay tau, s, >= 0.
        """
        a, ad = self._loop_matrices(k, t_s)
        return StepLoop(
            A=a,
            Ad=ad,
            b_r=np.array([0.0, 1.0]),  # dx_e/dt = r - dMAP
            bd_r=np.array([k * self.kp / t_s, 0.0]),  # the plant sees kp r(t - tau)
            c_map=np.array([1.0, 0.0]),
            c_u=np.array([-self.kp, self.ki]),
            d_u=self.kp,
            tau_s=float(tau_s),
        )

    def closed_loop(self, k: float, t_s: float, tau_s: float) -> DelaySystem:
        """The PI loop as a :class:`DelaySystem` for stability/LMI analysis.

        Exogenous input w: an output-side load d (mmHg) entering as T dMAP/dt = -dMAP + K u(t-tau) +
        d; performance output z = dMAP (mmHg), which the integral action drives back to zero (the
        closed-loop state matrices are what matter for stability; this channel keeps the L2 gain
        modest for the LMI).
        """
        a, ad = self._loop_matrices(k, t_s)
        return DelaySystem(
            A=a,
            Ad=ad,
            B=np.array([[1.0 / t_s], [0.0]]),
            C=np.array([[1.0, 0.0]]),
            Cd=np.zeros((1, 2)),
            D=np.zeros((1, 1)),
            tau=float(tau_s),
        )
