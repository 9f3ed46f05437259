"""The scheduled Smith law analysed in prediction-error coordinates, where the delay nearly cancels.

Why. The Wirtinger analysis of the shipped law in the plant's own coordinates
(:mod:`pressor.synthesis.families.smith.design`) sees a genuine delay loop, and certifies no delay box much
beyond τ = 60 s (docs/notes/certificate-structure.md, §4). A Smith predictor cancels the delay; written
in the coordinates of that cancellation, what is left of the delay is small, and the same analysis
reaches τ = 200 s (§5).

The laws (ρ = (K mmHg/(ml/h), T s, τ s) scheduled; u_a drives the filter ``u = Ω/(s + Λ) u_a``
whose state u (ml/h) is the infusion; g = K·Kc the loop gain, g_i = K·T·Ki = g unless set)::

    T dŷ/dt = −ŷ + K u                            delay-free model (mmHg)
    e_p     = r − MAP − ŷ + ŷ(t − τ)               predicted error (mmHg)
    exact:      u_a = Kc e_p + Ki q,  dq/dt = e_p                       Kc = g/K, Ki = g_i/(K T)
    trapezoid:  u_a = Kc e_p + Ki (x_e − τ(ŷ + ŷ(t − τ))/2),  dx_e/dt = r − MAP

"trapezoid" is the shipped law (:mod:`pressor.synthesis.families.smith.law`, in the synthesis controller
class); "exact" integrates the predicted error itself, ``q = x_e − ∫_{t−τ}^{t} ŷ``, a distributed
delay outside that class (:func:`simulate_law` runs it).

Coordinates. The plant ``T(t) dy/dt = −y + K(t) u(t − τ(t))`` and the prediction error
``e = y − ŷ(t − τ(t))``. Differentiating ``ŷ(t − τ(t))`` gives, exactly::

    de/dt = −e/T + α u(t − τ) + β ŷ(t − τ)
    α = K(t)/T(t) − (1 − τ̇) K(t − τ)/T(t − τ),    β = −1/T(t) + (1 − τ̇)/T(t − τ)

With ρ frozen α = β = 0 and e decays with the plant's own lag. The exact law's loop [u, ŷ, q] is
then the delay-free λ-loop, for every τ. The trapezoid keeps ŷ(t − τ) in its loop (in x_e and in
the trapezoid: :func:`loop_matrices`). With ρ moving, |α| and |β| are bounded by the rates times
τ̄ (:func:`perturbation_bounds`). In K-scaled coordinates ``x = [ũ = K u (mmHg), ŷ, q or x_e, e]``
the matrices depend on T and τ only (plus K̇/K on ũ), so the grid is two-dimensional, and the K box
enters only through the relative K rate ν_K/K_min.

The analysis is the project's Wirtinger LMI
(:func:`pressor.synthesis.certificates.wirtinger.analysis.analyse_wirtinger`, P affine in ρ̂ = (T, τ)) on these loops, each written at the vertices of K̇/K, α and β
(:func:`vertex_systems`). d is an additive output disturbance on MAP (mmHg) and z = e_p, so γ is
the certified L2 gain from an output disturbance to the predicted error (dimensionless; a different
channel from the shipped design's γ).

Units: K mmHg/(ml/h), T and τ s, rates per s; Ω, Λ 1/s.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pressor.synthesis.certificates.interface import AnalysisResult
from pressor.synthesis.problem.closed_loop import DelaySystem
from pressor.synthesis.problem.config import DesignConfig, ModelConfig

__all__ = [
    "LAWS",
    "PredictionErrorBox",
    "certify",
    "loop_matrices",
    "perturbation_bounds",
    "simulate_law",
    "vertex_systems",
]

Array = NDArray[np.float64]

#: states of the analysis: ũ = K u (mmHg), ŷ (mmHg), q (mmHg·s), e (mmHg)
N_STATES = 4
#: the laws certified: the exact integral of the predicted error, or the shipped trapezoid
LAWS = ("exact", "trapezoid")


@dataclass(frozen=True)
class PredictionErrorBox:
    """The scheduling box, rate bounds and law parameters the certificate is for.

    Attributes
    ----------
    k_min
        Smallest sensitivity K of the box (mmHg/(ml/h)), > 0; the relative K rate is
        ``k_rate / k_min``.
    t_range_s
        (low, high) of the lag T (s), 0 < low < high.
    tau_range_s
        (low, high) of the delay τ (s), 0 < low < high.
    rates
        |dK/dt| (mmHg/(ml/h)/s), |dT/dt| (s/s), |dτ/dt| (s/s), each >= 0, |dτ/dt| < 1.
    loop_gain
        g = K·Kc (dimensionless), > 0: the closed-loop time constant is λ = T/g.
    omega, lambda_
        The input filter ``u = omega/(s + lambda_) u_a`` (1/s), > 0.
    integral_gain
        g_i = K·T·Ki (dimensionless), > 0; None (default): g_i = g, the PI zero on the model's
        pole.
    law
        "exact" (default: the integral of the predicted error) or "trapezoid" (the shipped law:
        the raw error's integral x_e minus the trapezoid ``τ(ŷ + ŷ(t − τ))/2``).
    """

    k_min: float
    t_range_s: tuple[float, float]
    tau_range_s: tuple[float, float]
    rates: tuple[float, float, float]
    loop_gain: float
    omega: float
    lambda_: float
    integral_gain: float | None = None
    law: str = "exact"

    def __post_init__(self) -> None:
        if self.law not in LAWS:
            raise ValueError(f"law={self.law!r} must be one of {LAWS}")
        lo, hi = self.t_range_s
        d_lo, d_hi = self.tau_range_s
        checks = {
            "k_min": self.k_min > 0,
            "t_range_s": 0 < lo < hi,
            "tau_range_s": 0 < d_lo < d_hi,
            "rates": min(self.rates) >= 0 and self.rates[2] < 1,
            "loop_gain": self.loop_gain > 0,
            "omega": self.omega > 0,
            "lambda_": self.lambda_ > 0,
            "integral_gain": self.integral_gain is None or self.integral_gain > 0,
        }
        for name, ok in checks.items():
            value = getattr(self, name)
            if value is None:
                continue
            finite = np.all(np.isfinite(np.asarray(value, dtype=float)))
            if not (ok and finite):
                raise ValueError(f"{name}={value!r} outside its range (see PredictionErrorBox)")

    @property
    def g_i(self) -> float:
        """The integral gain g_i in use (``integral_gain``, else ``loop_gain``)."""
        return self.loop_gain if self.integral_gain is None else self.integral_gain

    @classmethod
    def from_config(cls, cfg: DesignConfig, law: str = "exact") -> PredictionErrorBox:
        """The box, rates, loop gain and filter of a design (``controller.loop_gain`` required)."""
        if cfg.controller.loop_gain is None:
            raise ValueError(f"{cfg.source}: controller.loop_gain is needed (the law's loop gain)")
        return cls.from_model(cfg.model, cfg.controller.loop_gain, law)

    @classmethod
    def from_model(cls, model: ModelConfig, loop_gain: float, law: str) -> PredictionErrorBox:
        """The box, rates and filter of ``model`` with ``loop_gain`` and ``law``."""
        box = np.asarray(model.box, dtype=float)
        rates = np.asarray(model.rate_bounds, dtype=float)
        return cls(
            k_min=float(box[0, 0]),
            t_range_s=(float(box[1, 0]), float(box[1, 1])),
            tau_range_s=(float(box[2, 0]), float(box[2, 1])),
            rates=(float(rates[0]), float(rates[1]), float(rates[2])),
            loop_gain=float(loop_gain),
            omega=float(model.omega),
            lambda_=float(model.lambda_),
            law=law,
        )


def loop_matrices(
    t_s: float, tau_s: float, k_rate_rel_per_s: float, box: PredictionErrorBox
) -> tuple[Array, Array]:
    """(A0, A1) per s: ``dx/dt = A0 x + A1 x(t − τ)`` on x = [ũ, ŷ, q or x_e, e] at lag T, delay τ.

    ``k_rate_rel_per_s`` is d(ln K)/dt. For the exact law A1 = 0 (the delay is gone); for the
    trapezoid, ``K u_a = g e_p + (g_i/T)(x_e − τ(ŷ + ŷ(t − τ))/2)`` with ``dx_e/dt = −ŷ(t − τ) − e``
    (the raw error integral, ``MAP = ŷ(t − τ) + e``) leaves ŷ(t − τ) in two places. The
    prediction-error perturbation (φ1 + φ2 in de/dt) and the disturbance are not included.
    """
    g, gi, om, lam = box.loop_gain, box.g_i, box.omega, box.lambda_
    # dũ/dt = (K̇/K − Λ) ũ + Ω K u_a,  K u_a = g e_p + (g_i/T) q,  e_p = −ŷ − e
    a0 = np.array(
        [
            [-lam + k_rate_rel_per_s, -om * g, om * gi / t_s, -om * g],
            [1.0 / t_s, -1.0 / t_s, 0.0, 0.0],
            [0.0, -1.0, 0.0, -1.0],
            [0.0, 0.0, 0.0, -1.0 / t_s],
        ]
    )
    a1 = np.zeros((N_STATES, N_STATES))
    if box.law == "trapezoid":
        half = om * gi * tau_s / (2.0 * t_s)
        a0[0, 1] -= half
        a1[0, 1] = -half
        a0[2, 1] = 0.0
        a1[2, 1] = -1.0
    return a0, a1


def perturbation_bounds(t_s: float, box: PredictionErrorBox) -> tuple[float, float]:
    """(a, b) per s: worst |α/K(t − τ)| and |β| at lag T over the rates and delays of the box.

    T(t − τ) lies within ``τ̄·|Ṫ|`` of T (and in the T box), K(t − τ) within ``τ̄·|K̇|`` of K(t)
    (the ratio is extreme at K = k_min), and τ̇ within ±|τ̇|_max. α and β are monotone in each of
    these, so the corners give the maxima.
    """
    lo, hi = box.t_range_s
    nu_k, nu_t, nu_tau = box.rates
    tau_max = box.tau_range_s[1]
    dk = tau_max * nu_k / box.k_min
    dt = tau_max * nu_t
    a = b = 0.0
    for ratio in (1.0 / (1.0 + dk), 1.0, 1.0 + dk):  # K(t) / K(t − τ)
        for t_d in (max(lo, t_s - dt), t_s, min(hi, t_s + dt)):  # T(t − τ)
            for tau_dot in (-nu_tau, 0.0, nu_tau):
                a = max(a, abs(ratio / t_s - (1.0 - tau_dot) / t_d))
                b = max(b, abs(-1.0 / t_s + (1.0 - tau_dot) / t_d))
    return a, b


def vertex_systems(
    box: PredictionErrorBox, t_points: int, tau_points: int
) -> tuple[list[DelaySystem], Array, Array, Array]:
    """The analysis inputs: closed loops in prediction-error coordinates at every grid point.

    The grid is geometric in T and uniform in τ over the box. At each point the loop is written
    once per vertex of the time-varying terms, all at the same ρ̂: d(ln K)/dt = ±ν_K/K_min (on ũ)
    and the perturbation ``φ = α' ũ(t − τ) + β ŷ(t − τ)`` at α' = ±a, β = ±b
    (:func:`perturbation_bounds`), as entries of the delayed matrix. The Wirtinger LMI is affine in
    A and A_d except for τ̄² ΓᵀRΓ, which is matrix-convex, so holding at these vertices it holds for
    every value between them. The states are [ũ, ŷ, q/T_ref, e] (T_ref the geometric mean of the T
    box: q, or x_e, moves T times slower than e_p, and in mmHg·s the LMI is badly conditioned).

    Returns
    -------
    (systems, rho_hat, rate_hat_per_s, dtau_drho_hat_s)
        For :func:`pressor.synthesis.certificates.wirtinger.analysis.analyse_wirtinger`: ρ̂ = (T, τ)
        normalised to [−1, 1], their rate bounds per s, and dτ/dρ̂ (s).
    """
    (t_lo, t_hi), (d_lo, d_hi) = box.t_range_s, box.tau_range_s
    t_ref = math.sqrt(t_lo * t_hi)
    scale, unscale = np.diag([1.0, 1.0, t_ref, 1.0]), np.diag([1.0, 1.0, 1.0 / t_ref, 1.0])
    g, om = box.loop_gain, box.omega
    b_d = unscale @ np.array([[-om * g], [0.0], [-1.0], [0.0]])  # d enters e_p and the raw error
    c_z = np.array([[0.0, -1.0, 0.0, -1.0]])  # z = e_p = −ŷ − e − d
    k_rel = box.rates[0] / box.k_min
    systems, rho = [], []
    for t_s in np.geomspace(t_lo, t_hi, t_points):
        a, b = perturbation_bounds(float(t_s), box)
        for tau_s in np.linspace(d_lo, d_hi, tau_points):
            for k_dot in (-k_rel, k_rel):
                a0, a1 = loop_matrices(float(t_s), float(tau_s), k_dot, box)
                for phi_u in (-a, a):
                    for phi_y in (-b, b):
                        ad = a1.copy()
                        ad[3, 0] += phi_u
                        ad[3, 1] += phi_y
                        systems.append(
                            DelaySystem(
                                unscale @ a0 @ scale,
                                unscale @ ad @ scale,
                                b_d,
                                c_z,
                                np.zeros((1, N_STATES)),
                                np.array([[-1.0]]),
                                float(tau_s),
                            )
                        )
                        rho.append(
                            [
                                2.0 * (t_s - t_lo) / (t_hi - t_lo) - 1.0,
                                2.0 * (tau_s - d_lo) / (d_hi - d_lo) - 1.0,
                            ]
                        )
    rate_hat = np.array([2.0 * box.rates[1] / (t_hi - t_lo), 2.0 * box.rates[2] / (d_hi - d_lo)])
    dtau = np.array([0.0, (d_hi - d_lo) / 2.0])
    return systems, np.array(rho), rate_hat, dtau


def certify(
    box: PredictionErrorBox,
    t_points: int = 3,
    tau_points: int = 3,
    time_scale_s: float = 60.0,
    gamma_cap: float | None = None,
) -> AnalysisResult:
    """The Wirtinger analysis (P affine in ρ̂ = (T, τ)) of :func:`vertex_systems`' loops.

    ``certified`` is the analysis' own re-check of every LMI at every point and vertex. With
    ``gamma_cap`` it is a feasibility solve at L2 gain <= the cap (how ``pressor verify`` checks a
    denser grid against a design's γ).

    Parameters
    ----------
    box
        What to certify.
    t_points, tau_points
        Grid points in T (geometric) and τ (uniform), each >= 2; the box's ends included.
    time_scale_s
        Time unit of the scaled problem (s), > 0.
    gamma_cap
        None: minimise γ; else the feasibility form at γ <= this.
    """
    from pressor.synthesis.certificates.wirtinger.analysis import analyse_wirtinger

    if t_points < 2 or tau_points < 2 or not time_scale_s > 0:
        raise ValueError(
            f"t_points={t_points} and tau_points={tau_points} must be >= 2 and "
            f"time_scale_s={time_scale_s} > 0"
        )
    systems, rho_hat, rate_hat, dtau = vertex_systems(box, t_points, tau_points)
    return analyse_wirtinger(
        systems,
        rho_hat,
        rate_hat,
        dtau,
        box.tau_range_s[1],
        p_dependence="affine",
        time_scale_s=time_scale_s,
        gamma_cap=gamma_cap,
    )


def simulate_law(
    box: PredictionErrorBox,
    schedule: Callable[[float], tuple[float, float, float]],
    duration_s: float,
    disturbance_mmhg: float = 10.0,
    disturbance_s: float = math.inf,
    dt_s: float = 0.05,
) -> tuple[Array, Array]:
    """Run the law of the module docstring on the plant ρ(t) describes (explicit Euler).

    The plant ``T(t) dy/dt = −y + K(t) u(t − τ(t))`` and the law both follow ``schedule`` (the
    scheduled ρ equals the plant's, as the certificate assumes); the target is 0 and an output
    disturbance ``disturbance_mmhg`` acts on MAP for 0 <= t < ``disturbance_s`` (s), everything
    at rest before. After it the loop is unforced, so the certificate says it decays to 0.

    Returns
    -------
    (times_s, map_mmhg)
        The sample times (s) and the measured MAP deviation (mmHg), disturbance included.
    """
    steps = int(round(duration_s / dt_s))
    u_hist = np.zeros(steps + 1)
    yhat_hist = np.zeros(steps + 1)
    y = q = 0.0
    times = np.arange(steps + 1) * dt_s
    measured = np.zeros(steps + 1)

    def delayed(hist: Array, k: int, tau_s: float) -> float:
        pos = k - tau_s / dt_s
        if pos <= 0.0:
            return 0.0
        i = int(math.floor(pos))
        f = pos - i
        return float(hist[i] * (1.0 - f) + hist[min(i + 1, k)] * f)

    for k in range(steps):
        kk, t_s, tau_s = schedule(times[k])
        u, yhat = u_hist[k], yhat_hist[k]
        measured[k] = y + (disturbance_mmhg if times[k] < disturbance_s else 0.0)
        e_p = -measured[k] - yhat + delayed(yhat_hist, k, tau_s)
        u_a = (box.loop_gain * e_p + box.g_i / t_s * q) / kk
        u_hist[k + 1] = u + dt_s * (-box.lambda_ * u + box.omega * u_a)
        yhat_hist[k + 1] = yhat + dt_s * (-yhat + kk * u) / t_s
        y += dt_s * (-y + kk * delayed(u_hist, k, tau_s)) / t_s
        q += dt_s * e_p
    measured[steps] = y + (disturbance_mmhg if times[steps] < disturbance_s else 0.0)
    return times, measured
