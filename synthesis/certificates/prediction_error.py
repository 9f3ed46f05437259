"""A certificate in prediction-error coordinates: the Smith law that integrates the predicted error.

Why a second certificate. The Wirtinger analysis of the shipped law
(:mod:`synthesis.certificates.wirtinger.analysis`) bounds ∫ over [t − τ, t] of the closed loop's
state, so its difficulty grows with the delay: it certifies no box much beyond τ = 60 s
(docs/CERTIFICATE-STRUCTURE.md, §4). A Smith predictor cancels the delay, and in the right
coordinates the delay is only left in terms that the *rates* of ρ make nonzero. This module
certifies the law in those coordinates; its condition depends on τ̄ only through how far ρ can
move within one delay (``rate × τ̄``), not through τ̄ itself.

The law (ρ = (K mmHg/(ml/h), T s, τ s) scheduled; u_a is the input of the filter
``u = Ω/(s + Λ) u_a`` whose state u (ml/h) is the infusion; loop gain g = K·Kc)::

    T dŷ/dt = −ŷ + K u                            delay-free model (mmHg)
    e_p     = r − MAP − ŷ + ŷ(t − τ)               predicted error (mmHg)
    dq/dt   = e_p                                  its integral (mmHg·s)
    u_a     = Kc e_p + Ki q,   Kc = g/K,   Ki = g_i/(K T)   (g_i = g unless set)

This is the scheduled PI-on-predicted-error of :mod:`synthesis.families.smith.law` with the exact
integral ``q = x_e − ∫_{t−τ}^{t} ŷ`` in place of that module's trapezoid (a distributed delay:
not in the synthesis controller class, so not the shipped law; :func:`simulate_law` runs it).

Coordinates. The plant ``T(t) dy/dt = −y + K(t) u(t − τ(t))`` and the prediction error
``e = y − ŷ(t − τ(t))``. Differentiating ``ŷ(t − τ(t))`` gives, exactly::

    de/dt = −e/T + α u(t − τ) + β ŷ(t − τ)
    α = K(t)/T(t) − (1 − τ̇) K(t − τ)/T(t − τ),    β = −1/T(t) + (1 − τ̇)/T(t − τ)

With ρ frozen α = β = 0: e decays with the plant's own lag and the loop [u, ŷ, q] is the
delay-free λ-loop, stable for every τ. With ρ moving, |α| and |β| are bounded by the rates times
τ̄ (:func:`perturbation_bounds`). In K-scaled coordinates ``x = [ũ = K u (mmHg), ŷ, q, e]`` the
loop matrix depends on T only (plus the term K̇/K on ũ), so the grid is one-dimensional in T and
the lower end of the K box enters only through the relative K rate ν_K/K_min.

The LMI (per T grid point, shared multipliers over the rate vertices; time in units of
``time_scale_s``)::

    V = xᵀ P(T) x + ∫_{t−τ}^{t} xᵀ Q x,   P(T) = P0 + θ P1 + θ² P2,  θ = T normalised to [−1, 1]
    φ1 = α' ũ(t − τ), |α'| ≤ a;   φ2 = β ŷ(t − τ), |β| ≤ b;   de/dt gets φ1 + φ2
    V̇ + z² − γ² d² < 0 for all |φ1| ≤ a|ũ_d|, |φ2| ≤ b|ŷ_d|   (S-procedure, λ1, λ2 ≥ 0)

with d an additive output disturbance on MAP (mmHg) and z = e_p: γ is the certified L2 gain from an
output disturbance to the predicted error (dimensionless). ``Q`` is constant (a delay-independent
Krasovskii term), so the LMI holds for every τ(t) in [0, τ̄] with |τ̇| ≤ ν_τ < 1.

Units: K mmHg/(ml/h), T and τ s, rates per s; Ω, Λ 1/s.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from synthesis.problem.config import DesignConfig

__all__ = [
    "PredictionErrorBox",
    "PredictionErrorCertificate",
    "certify",
    "loop_matrix",
    "perturbation_bounds",
    "simulate_law",
]

Array = NDArray[np.float64]

#: states of the analysis: ũ = K u (mmHg), ŷ (mmHg), q (mmHg·s), e (mmHg)
N_STATES = 4
#: strictness margin of every LMI in the γ-minimising solve (scaled units)
EPSILON = 1e-7
#: γ is certified at (1 + this) × the minimum, where the LMIs have room to spare
GAMMA_BACKOFF = 0.05


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
    tau_max_s
        Longest delay τ̄ (s), >= 0; any τ(t) in [0, τ̄] is covered.
    rates
        |dK/dt| (mmHg/(ml/h)/s), |dT/dt| (s/s), |dτ/dt| (s/s), each >= 0, |dτ/dt| < 1.
    loop_gain
        g = K·Kc (dimensionless), > 0: the closed-loop time constant is λ = T/g.
    omega, lambda_
        The input filter ``u = omega/(s + lambda_) u_a`` (1/s), > 0.
    integral_gain
        g_i = K·T·Ki (dimensionless), > 0; None (default): g_i = g, the PI zero on the model's
        pole.
    """

    k_min: float
    t_range_s: tuple[float, float]
    tau_max_s: float
    rates: tuple[float, float, float]
    loop_gain: float
    omega: float
    lambda_: float
    integral_gain: float | None = None

    def __post_init__(self) -> None:
        lo, hi = self.t_range_s
        checks = {
            "k_min": self.k_min > 0,
            "t_range_s": 0 < lo < hi,
            "tau_max_s": self.tau_max_s >= 0,
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
    def from_config(cls, cfg: DesignConfig) -> PredictionErrorBox:
        """The box, rates, loop gain and filter of a design (``controller.loop_gain`` required)."""
        if cfg.controller.loop_gain is None:
            raise ValueError(f"{cfg.source}: controller.loop_gain is needed (the law's loop gain)")
        box = np.asarray(cfg.model.box, dtype=float)
        rates = np.asarray(cfg.model.rate_bounds, dtype=float)
        return cls(
            k_min=float(box[0, 0]),
            t_range_s=(float(box[1, 0]), float(box[1, 1])),
            tau_max_s=float(box[2, 1]),
            rates=(float(rates[0]), float(rates[1]), float(rates[2])),
            loop_gain=float(cfg.controller.loop_gain),
            omega=float(cfg.model.omega),
            lambda_=float(cfg.model.lambda_),
        )


@dataclass(frozen=True)
class PredictionErrorCertificate:
    """Outcome of :func:`certify`.

    Attributes
    ----------
    certified
        Clarabel reported "optimal" and every LMI, re-evaluated in numpy, is negative definite with
        every P(T_k) positive definite.
    status
        Clarabel's outcome as a cvxpy status string.
    gamma
        Certified L2 gain, output disturbance (mmHg) to predicted error (mmHg); None on failure.
    t_grid_s
        The T points (s) of the check grid (the design points and those between them).
    margins
        Smallest ``-λ_max`` of the LMI at each check point over its rate vertices (scaled units);
        NaN when the solve failed.
    p_terms, q
        P0, P1, P2 (3, 4, 4) and Q (4, 4) in the scaled coordinates (time in ``time_scale_s``,
        q in mmHg·T_ref with T_ref the T box's geometric mean); None on failure.
    solve_time_s
        Assembly and solve time (s).
    """

    certified: bool
    status: str
    gamma: float | None
    t_grid_s: Array
    margins: Array
    p_terms: Array | None
    q: Array | None
    solve_time_s: float


def loop_matrix(t_s: float, k_rate_rel_per_s: float, box: PredictionErrorBox) -> Array:
    """The loop matrix (per s) on x = [ũ, ŷ, q, e] at lag T with d(ln K)/dt = ``k_rate_rel``.

    The prediction-error perturbation (φ1 + φ2 in de/dt) and the disturbance are not included.
    """
    g, gi, om, lam = box.loop_gain, box.g_i, box.omega, box.lambda_
    # dũ/dt = (K̇/K − Λ) ũ + Ω K u_a,  K u_a = g e_p + (g_i/T) q,  e_p = −ŷ − e
    return np.array(
        [
            [-lam + k_rate_rel_per_s, -om * g, om * gi / t_s, -om * g],
            [1.0 / t_s, -1.0 / t_s, 0.0, 0.0],
            [0.0, -1.0, 0.0, -1.0],
            [0.0, 0.0, 0.0, -1.0 / t_s],
        ]
    )


def perturbation_bounds(t_s: float, box: PredictionErrorBox) -> tuple[float, float]:
    """(a, b) per s: worst |α/K(t − τ)| and |β| at lag T over the rates and delays of the box.

    T(t − τ) lies within ``τ̄·|Ṫ|`` of T (and in the T box), K(t − τ) within ``τ̄·|K̇|`` of K(t)
    (the ratio is extreme at K = k_min), and τ̇ within ±|τ̇|_max. α and β are monotone in each of
    these, so the corners give the maxima.
    """
    lo, hi = box.t_range_s
    nu_k, nu_t, nu_tau = box.rates
    dk = box.tau_max_s * nu_k / box.k_min
    dt = box.tau_max_s * nu_t
    a = b = 0.0
    for ratio in (1.0 / (1.0 + dk), 1.0, 1.0 + dk):  # K(t) / K(t − τ)
        for t_d in (max(lo, t_s - dt), t_s, min(hi, t_s + dt)):  # T(t − τ)
            for tau_dot in (-nu_tau, 0.0, nu_tau):
                a = max(a, abs(ratio / t_s - (1.0 - tau_dot) / t_d))
                b = max(b, abs(-1.0 / t_s + (1.0 - tau_dot) / t_d))
    return a, b


def certify(
    box: PredictionErrorBox, t_points: int = 9, check_factor: int = 4, time_scale_s: float = 60.0
) -> PredictionErrorCertificate:
    """Solve the LMI of the module docstring on ``t_points`` geometric T points; re-check densely.

    γ is minimised, then certified at (1 + :data:`GAMMA_BACKOFF`) × the minimum with the margin
    maximised; the certificate (P, Q) is then re-checked in numpy at ``check_factor`` times as many
    intervals of T (every design point included), where ``margins`` are reported.

    Parameters
    ----------
    box
        What to certify.
    t_points
        Number of T design points, >= 2 (geometric over the T box; the ends included).
    check_factor
        Check-grid refinement, >= 1 (1: the design points only).
    time_scale_s
        Time unit of the scaled problem (s), > 0.
    """
    if t_points < 2 or check_factor < 1 or not time_scale_s > 0:
        raise ValueError(
            f"t_points={t_points} must be >= 2, check_factor={check_factor} >= 1 and "
            f"time_scale_s={time_scale_s} > 0"
        )
    start = time.perf_counter()
    tu = float(time_scale_s)
    lo, hi = box.t_range_s
    ts = np.geomspace(lo, hi, t_points)
    theta = 2.0 * (ts - lo) / (hi - lo) - 1.0
    dtheta = 2.0 * box.rates[1] / (hi - lo) * tu  # |dθ/d(scaled time)|
    k_rel = box.rates[0] / box.k_min
    blocks = _Blocks(box, tu)
    status, g2_opt, _, _ = _solve(blocks, ts, theta, dtheta, k_rel, None)
    if g2_opt is None:
        return _failed(status, ts, start)
    # γ at the optimum puts the LMIs on their boundary; back off and maximise the margin instead
    g2 = g2_opt * (1.0 + GAMMA_BACKOFF) ** 2
    status, _, p_val, q_val = _solve(blocks, ts, theta, dtheta, k_rel, g2)
    if p_val is None or q_val is None:
        return _failed(status, ts, start)
    check_ts = np.geomspace(lo, hi, (t_points - 1) * check_factor + 1)
    check_theta = 2.0 * (check_ts - lo) / (hi - lo) - 1.0
    margins = np.array(
        [
            blocks.margin(t_s, th, p_val, q_val, g2, k_rel, dtheta)
            for t_s, th in zip(check_ts, check_theta, strict=True)
        ]
    )
    p_ok = all(
        np.linalg.eigvalsh(p_val[0] + th * p_val[1] + th**2 * p_val[2])[0] > 0 for th in check_theta
    )
    ok = bool(np.all(margins > 0) and p_ok and np.linalg.eigvalsh(q_val)[0] > 0)
    return PredictionErrorCertificate(
        ok, status, math.sqrt(g2), check_ts, margins, p_val, q_val, time.perf_counter() - start
    )


def _failed(status: str, ts: Array, start: float) -> PredictionErrorCertificate:
    nan = np.full(ts.size, np.nan)
    return PredictionErrorCertificate(
        False, status, None, ts, nan, None, None, time.perf_counter() - start
    )


def _solve(
    blocks: _Blocks,
    ts: Array,
    theta: Array,
    dtheta: float,
    k_rel: float,
    gamma2_fixed: float | None,
) -> tuple[str, float | None, Array | None, Array | None]:
    """One solve: min γ² at margin EPSILON (``gamma2_fixed`` None), else max margin at that γ².

    Returns (status, γ², P terms, Q); the values are None unless the status is "optimal".
    """
    import cvxpy as cp

    n = N_STATES
    p_terms = [cp.Variable((n, n), symmetric=True) for _ in range(3)]
    q = cp.Variable((n, n), symmetric=True)
    if gamma2_fixed is None:
        gamma2: object = cp.Variable(nonneg=True)
        margin: object = EPSILON
        objective = cp.Minimize(gamma2)
    else:
        gamma2 = gamma2_fixed
        margin = cp.Variable()
        objective = cp.Maximize(margin)
    cons = [q >> margin * np.eye(n)]
    if gamma2_fixed is not None:
        cons.append(margin <= 1.0)
    for t_s, th in zip(ts, theta, strict=True):
        p = p_terms[0] + th * p_terms[1] + th**2 * p_terms[2]
        dp = p_terms[1] + 2.0 * th * p_terms[2]
        cons.append(p >> margin * np.eye(n))
        mult = cp.Variable(2, nonneg=True)
        for k_dot in (-k_rel, k_rel):
            for th_dot in (-dtheta, dtheta):
                m = blocks.lmi(cp, t_s, k_dot, p, th_dot * dp, q, mult, gamma2)
                cons.append((m + m.T) / 2 << -margin * np.eye(m.shape[0]))
    problem = cp.Problem(objective, cons)
    try:
        with warnings.catch_warnings():  # "inaccurate" is reported through the status below
            warnings.simplefilter("ignore", UserWarning)
            problem.solve(solver="CLARABEL")
    except cp.error.SolverError as exc:
        return f"solver error: {exc}", None, None, None
    status = str(problem.status)
    if status != "optimal":
        return status, None, None, None
    g2 = float(gamma2.value) if isinstance(gamma2, cp.Variable) else float(gamma2)  # type: ignore[arg-type]
    return status, g2, np.array([v.value for v in p_terms]), np.asarray(q.value)


class _Blocks:
    """The LMI matrix at one T point and rate vertex, for cvxpy variables or numpy values."""

    def __init__(self, box: PredictionErrorBox, tu: float) -> None:
        self.box, self.tu = box, tu
        n = N_STATES
        self.e_phi = np.zeros((n, 1))
        self.e_phi[3, 0] = 1.0  # φ1 and φ2 (scaled) both enter de/dt
        g, om = box.loop_gain, box.omega
        # q is measured in units of mmHg·T_ref (T_ref the geometric mean of the T box): q moves
        # T times slower than e_p, and in mmHg·s the certificate's P is too badly conditioned
        t_ref = math.sqrt(box.t_range_s[0] * box.t_range_s[1])
        self.scale = np.diag([1.0, 1.0, t_ref, 1.0])
        self.unscale = np.diag([1.0, 1.0, 1.0 / t_ref, 1.0])
        # d enters e_p with −1
        self.e_d = self.unscale @ np.array([[-om * g], [0.0], [-1.0], [0.0]]) * tu
        self.c_z = np.array([[0.0, -1.0, 0.0, -1.0]])  # z = e_p = −ŷ − e (− d); q not in it

    def _pieces(self, t_s: float, k_dot: float) -> tuple[Array, Array, Array]:
        a_mat = self.unscale @ loop_matrix(t_s, k_dot, self.box) @ self.scale * self.tu
        a, b = perturbation_bounds(t_s, self.box)
        sel_u = np.zeros((N_STATES, N_STATES))
        sel_u[0, 0] = (a * self.tu) ** 2
        sel_y = np.zeros((N_STATES, N_STATES))
        sel_y[1, 1] = (b * self.tu) ** 2
        return a_mat, sel_u, sel_y

    def lmi(
        self, cp: Any, t_s: float, k_dot: float, p: Any, p_dot: Any, q: Any, mult: Any, gamma2: Any
    ) -> Any:
        """The (2n + 3)-square LMI matrix at lag ``t_s`` (s), ``k_dot`` = d(ln K)/dt per s.

        ``p``, ``p_dot``, ``q``, ``mult`` (2,) and ``gamma2`` are cvxpy expressions or numpy
        values; the result is a cvxpy expression (``.value`` evaluates it for numpy inputs).
        """
        n = N_STATES
        a_mat, sel_u, sel_y = self._pieces(t_s, k_dot)
        zn, z1n, z11 = np.zeros((n, n)), np.zeros((1, n)), np.zeros((1, 1))
        c, dz = self.c_z, np.array([[-1.0]])
        top = p @ a_mat + a_mat.T @ p + p_dot + q + c.T @ c
        pe, pd = p @ self.e_phi, p @ self.e_d + c.T @ dz
        delayed = -(1.0 - self.box.rates[2]) * q + mult[0] * sel_u + mult[1] * sel_y
        return cp.bmat(
            [
                [top, zn, pe, pe, pd],
                [zn, delayed, z1n.T, z1n.T, z1n.T],
                [pe.T, z1n, cp.reshape(-mult[0], (1, 1), order="C"), z11, z11],
                [pe.T, z1n, z11, cp.reshape(-mult[1], (1, 1), order="C"), z11],
                [pd.T, z1n, z11, z11, dz.T @ dz - cp.reshape(gamma2, (1, 1), order="C")],
            ]
        )

    def margin(
        self, t_s: float, th: float, p_terms: Array, q: Array, g2: float, k_rel: float, dth: float
    ) -> float:
        """Smallest ``-λ_max`` (numpy) over the rate vertices at P, Q, γ² fixed (scaled units).

        Only the two multipliers are re-chosen (a small SDP maximising the margin), and the matrices
        are then re-evaluated in numpy, so the figure does not trust the solver's accuracy.
        """
        import cvxpy as cp

        p = p_terms[0] + th * p_terms[1] + th**2 * p_terms[2]
        dp = p_terms[1] + 2.0 * th * p_terms[2]
        mult = cp.Variable(2, nonneg=True)
        t = cp.Variable()
        vertices = [(k, d) for k in (-k_rel, k_rel) for d in (-dth, dth)]
        cons: list[object] = [t <= 1.0]
        for k_dot, th_dot in vertices:
            m = self.lmi(cp, t_s, k_dot, p, th_dot * dp, q, mult, g2)
            cons.append((m + m.T) / 2 << -t * np.eye(m.shape[0]))
        with warnings.catch_warnings():  # an inaccurate solve is fine: numpy re-checks it below
            warnings.simplefilter("ignore", UserWarning)
            cp.Problem(cp.Maximize(t), cons).solve(solver="CLARABEL")
        if mult.value is None:
            return -math.inf
        fixed = np.maximum(np.asarray(mult.value, dtype=float), 0.0)
        worst = math.inf
        for k_dot, th_dot in vertices:
            m = np.asarray(self.lmi(cp, t_s, k_dot, p, th_dot * dp, q, fixed, g2).value)
            worst = min(worst, -float(np.linalg.eigvalsh((m + m.T) / 2)[-1]))
        return worst


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
