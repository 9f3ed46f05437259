"""A scheduled Smith predictor with a PI on the predicted output, written in the LPV controller class.

The synthesis controller class (:class:`pressor.synthesis.problem.reconstruct.DelayedController`) is::

    dx_k/dt = Ak x_k + Adk x_k(t − τ) + Bk y,     u_a = Ck x_k + Cdk x_k(t − τ) + Dk y

with ``y = [e (mmHg), x_e (mmHg·s)]`` and the input filter ``u = Ω/(s + Λ) u_a`` part of the plant
(:mod:`pressor.synthesis.problem.model`). This module writes the control engineer's alternative in that
class, so that the same closed-loop tools (:func:`pressor.synthesis.problem.closed_loop.close_loop`, the
analysis LMI, the frozen-delay roots, the step simulation) apply to it unchanged.

Law at a frozen ρ = (K, T, τ). The controller state ``x_k = [û (ml/h), ŷ (mmHg)]`` is the
delay-free model of the plant *including the input filter*::

    dû/dt = −Λ û + Ω u_a,     T dŷ/dt = −ŷ + K û

The predicted error is ``e_p = e − ŷ + ŷ(t − τ)`` and the PI acts on it,
``u_a = Kc e_p + Ki ∫e_p``. The integral of the prediction correction is
``∫(ŷ − ŷ(t − τ)) = ∫_{t−τ}^{t} ŷ``, a distributed delay outside the class; it is replaced by the
trapezoid ``τ (ŷ + ŷ(t − τ)) / 2`` (error ``τ³ ÿ/12``, small since ŷ moves on the scale T ≫ τ), so::

    u_a = Kc (e − ŷ + ŷ(t − τ)) + Ki (x_e − τ (ŷ + ŷ(t − τ)) / 2)

Why not the exact integral as a third state ``dq/dt = ŷ − ŷ(t − τ)``: then ``x_e = q = c`` is an
equilibrium for every constant c (the controller output only sees ``x_e − q``), a closed-loop
eigenvalue at 0, and no strict Lyapunov certificate exists. The trapezoid keeps x_e the only
integrator, so the closed loop can be asymptotically stable.

Tuning: ``Kc = T/(K λ)``, ``Ti = T`` (``Ki = Kc/Ti = 1/(K λ)``), the rule of
:mod:`pressor.baselines.smith`; the PI zero cancels the model's T pole and the delay-free loop is
``1/(λ s (s/Λ + 1) + 1)`` when Ω = Λ. The closed-loop time constant is scheduled as
``λ = T / loop_gain``: ``loop_gain = K·Kc`` is then the same at every ρ, which is what the
closed-loop dynamics depend on (a fixed λ makes the loop faster, relative to the plant, where T is
large). At τ = 0 the law reduces to the PI ``u_a = Kc e + Ki x_e``.

The bumpless integral (designs with a relative K rate, ``[rates] K_relative_per_s``). The gains
are ``Kc = g/K``, ``Ki = g/(K T)``: when the scheduled K moves, u_a = (g/K)(e_p + (x_e − Q)/T)
(``Q = τ(ŷ + ŷ(t − τ))/2``) would move with it, a falling K pushing harder on the error and the
integral already accumulated at the old gain. The generated module keeps u_a continuous instead:
at every tick its K moves from K to K' the integral becomes
``x_e' = ρ x_e + (1 − ρ)(Q − T e_p)``, ``ρ = K'/K``, so the command changes only through the
error that follows (velocity form). In continuous time that is ``dx_e/dt = e + κ (K T / g) u_a``,
κ = d(ln K)/dt: the term the certificate carries
(:func:`pressor.synthesis.families.smith.design.bumpless_rows`). A frozen ρ is unchanged: the frozen
loops, roots and nominal step are this module's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pressor.synthesis.problem.closed_loop import OutputFeedback

__all__ = ["SmithLPV"]


@dataclass(frozen=True)
class SmithLPV:
    """The Smith predictor + PI as a delayed controller on y = [e; x_e], scheduled on ρ.

    Parameters
    ----------
    loop_gain
        Proportional loop gain ``K·Kc = T/λ`` (dimensionless), > 0; the closed-loop time
        constant is λ = T / loop_gain (s); on the nominal plant (T = 150 s): 1.5 -> λ = 100 s,
        2 -> 75 s, 3 -> 50 s, 5 -> 30 s.
    omega, lambda_
        The input filter ``u = omega/(s + lambda_) u_a`` of the plant model (1/s), > 0.
    """

    loop_gain: float
    omega: float = 0.1
    lambda_: float = 0.1

    def __post_init__(self) -> None:
        for name in ("loop_gain", "omega", "lambda_"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0.0):
                raise ValueError(f"{name}={v!r} must be finite and > 0")

    def gains(self, k: float, t_s: float) -> tuple[float, float]:
        """``(Kc (ml/h)/mmHg, Ki (ml/h)/(mmHg·s))`` at sensitivity K (mmHg/(ml/h)) and lag T (s)."""
        if not (np.isfinite(k) and np.isfinite(t_s) and k > 0.0 and t_s > 0.0):
            raise ValueError(f"K={k!r} and T={t_s!r} must be finite and > 0")
        lam = t_s / self.loop_gain
        return t_s / (k * lam), 1.0 / (k * lam)

    def at(self, rho: tuple[float, float, float] | NDArray[np.float64]) -> OutputFeedback:
        """The controller matrices at ρ = (K [mmHg/(ml/h)], T [s], τ [s]), physical units.

        Returns the matrices (states û ml/h, ŷ mmHg) in the form
        :func:`pressor.synthesis.problem.closed_loop.close_loop` accepts.
        """
        k, t_s, tau_s = (float(v) for v in np.asarray(rho, dtype=float).reshape(3))
        if not (np.isfinite(tau_s) and tau_s >= 0.0):
            raise ValueError(f"tau={tau_s!r} must be finite and >= 0 s")
        kc, ki = self.gains(k, t_s)
        ck = np.array([[0.0, -kc - 0.5 * ki * tau_s]])
        cdk = np.array([[0.0, kc - 0.5 * ki * tau_s]])
        dk = np.array([[kc, ki]])
        b_model = np.array([[self.omega], [0.0]])  # u_a drives the model's filter state û
        a_model = np.array([[-self.lambda_, 0.0], [k / t_s, -1.0 / t_s]])
        return OutputFeedback(
            Ak=a_model + b_model @ ck,
            Adk=b_model @ cdk,
            Bk=b_model @ dk,
            Ck=ck,
            Cdk=cdk,
            Dk=dk,
        )
