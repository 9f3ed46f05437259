"""First-order descriptions of an independent patient (:mod:`pressor.hil_sim.patients.pkpd`) that a perfect
identification would give: the bounds of the scheduling-source benchmark.

* :func:`apparent_fopdt`: in closed form, K the steady secant gain, T the sum of the two fast
  lags, τ the line delay alone (``lpv-truth``).
* :func:`step_response_fit`: the K, T, τ whose step response is closest (least squares) to the
  patient's own over a window (``lpv-stepfit``). The fit puts the effect-site and plasma lags that a
  first-order model cannot carry into τ, and K is the gain reached within the window, so the creep
  after it does not count.
* :func:`incremental_gain`: the local sensitivity at the operating point (``lpv-stepfit-inc``).

Units: t in s, MAP changes in mmHg, rates in ml/h, K in mmHg/(ml/h). The defaults are the
benchmark's: 0.1 s steps, a 100 µg/ml syringe, a 120 ml/h pump.
"""

from __future__ import annotations

import random

import numpy as np

from pressor.hil_sim.patients.pkpd import IndependentPatient, PatientParams

#: the benchmark's sample period (s), syringe (µg/ml) and pump limit (ml/h)
STEP_S = 0.1
CONCENTRATION_UG_ML = 100.0
PUMP_MAX_ML_H = 120.0

#: the fit's search grid: τ in s, T in s (K is solved in closed form at each grid point)
TAU_GRID_S = np.arange(0.0, 240.0 + 1e-9, 2.0)
T_GRID_S = np.arange(20.0, 1000.0 + 1e-9, 10.0)
#: the open-loop step's length (s): 10 min, the first part of the plasma's creep included
WINDOW_S = 600.0


def fit_fopdt(
    t_s: np.ndarray,
    delta_map_mmhg: np.ndarray,
    rate_ml_h: float,
    tau_grid_s: np.ndarray = TAU_GRID_S,
    T_grid_s: np.ndarray = T_GRID_S,
) -> tuple[float, float, float]:
    """The (K, T s, τ s) minimising Σ (Δy(t) − K·u·(1 − e^(−(t − τ)/T))⁺)² over the grids.

    Parameters
    ----------
    t_s, delta_map_mmhg
        Sample times (s, from the step) and the MAP's change from its pre-step value (mmHg).
    rate_ml_h
        The step's rate (ml/h), > 0.
    tau_grid_s, T_grid_s
        Candidate delays (s, >= 0) and lags (s, > 0).

    Returns
    -------
    tuple of float
        K (mmHg/(ml/h)), T (s), τ (s) of the best grid point (K exact for that τ, T).
    """
    if not rate_ml_h > 0.0:
        raise ValueError(f"rate_ml_h={rate_ml_h!r} must be > 0")
    t = np.asarray(t_s, dtype=float)
    y = np.asarray(delta_map_mmhg, dtype=float)
    best = (np.inf, 0.0, 0.0, 0.0)
    for tau in tau_grid_s:
        s = np.clip(t - tau, 0.0, None)[:, None]
        phi = 1.0 - np.exp(-s / np.asarray(T_grid_s)[None, :])  # one column per T
        pp = np.einsum("ij,ij->j", phi, phi)
        py = phi.T @ y
        gain = np.divide(py, pp, out=np.zeros_like(py), where=pp > 0.0)
        sse = y @ y - gain * py  # the residual at the closed-form gain
        j = int(np.argmin(sse))
        if sse[j] < best[0]:
            best = (float(sse[j]), float(gain[j]) / rate_ml_h, float(T_grid_s[j]), float(tau))
    return best[1], best[2], best[3]


def held_patient(
    params: PatientParams,
    target_mmhg: float,
    step_s: float = STEP_S,
    concentration_ug_ml: float = CONCENTRATION_UG_ML,
    max_rate_ml_h: float = PUMP_MAX_ML_H,
) -> tuple[IndependentPatient, float]:
    """A fresh patient of ``params`` without disturbances, and the rate (ml/h) that holds
    ``target_mmhg`` at steady state (the pump's limit when the target is out of reach)."""
    patient = IndependentPatient(params, step_s, concentration_ug_ml, disturbances=False)
    return patient, patient.steady_state_rate_ml_h(target_mmhg, max_rate_ml_h) or max_rate_ml_h


def apparent_fopdt(params: PatientParams, target_mmhg: float) -> tuple[float, float, float]:
    """The patient's apparent FOPDT held at ``target_mmhg``: K the secant sensitivity (target −
    baseline) / the steady infusion that holds the target (mmHg/(ml/h)), T the plasma's fast time
    constant V1/(CL + Q) plus the effect-site lag (s), τ the transport delay (s)."""
    need = held_patient(params, target_mmhg)[1]
    K = (target_mmhg - params.baseline_mmhg) / max(need, 1e-6)
    T = 60.0 * params.v1_l / (params.cl_l_min + params.q_l_min) + params.effect_lag_s
    return K, T, params.delay_s


def incremental_gain(params: PatientParams, target_mmhg: float) -> float:
    """The patient's local sensitivity at the rate that holds ``target_mmhg`` (mmHg/(ml/h), the
    plasma's fast mode settled, the peripheral level and the tolerance not yet moved:
    :meth:`~pressor.hil_sim.patients.pkpd.IndependentPatient.fast_gain_mmhg_per_ml_h`)."""
    patient, need = held_patient(params, target_mmhg)
    return patient.fast_gain_mmhg_per_ml_h(need)


def step_response_fit(
    params: PatientParams,
    target_mmhg: float,
    step_s: float = STEP_S,
    concentration_ug_ml: float = CONCENTRATION_UG_ML,
    max_rate_ml_h: float = PUMP_MAX_ML_H,
    window_s: float = WINDOW_S,
    rate_ml_h: float | None = None,
    noise_mmhg: float = 0.0,
    seed: int = 0,
) -> tuple[float, float, float]:
    """:func:`fit_fopdt` of the patient's open-loop response, disturbances off, over ``window_s``
    s sampled every ``step_s`` s.

    By default the ideal device: the rate that holds ``target_mmhg`` at steady state (the pump's
    limit when out of reach), noise-free. A realistic one gives ``rate_ml_h`` (a test rate chosen
    without knowing the patient, (0, ``max_rate_ml_h``]) and ``noise_mmhg`` (the monitor's
    Gaussian noise, mmHg, >= 0, drawn from ``random.Random(seed)``; the pre-step level is then the
    mean of 10 s of noisy samples)."""
    patient, rate = held_patient(params, target_mmhg, step_s, concentration_ug_ml, max_rate_ml_h)
    if rate_ml_h is not None:
        if not 0.0 < rate_ml_h <= max_rate_ml_h:
            raise ValueError(f"rate_ml_h={rate_ml_h!r} outside (0, {max_rate_ml_h}] ml/h")
        rate = rate_ml_h
    if not noise_mmhg >= 0.0:
        raise ValueError(f"noise_mmhg={noise_mmhg!r} must be >= 0 mmHg")
    rng = random.Random(seed)
    n0 = round(10.0 / step_s)
    y0 = patient.map_mmhg
    if noise_mmhg > 0.0:
        y0 += sum(rng.gauss(0.0, noise_mmhg) for _ in range(n0)) / n0
    n = round(window_s / step_s)
    dy = np.empty(n)
    for k in range(n):
        dy[k] = patient.map_mmhg - y0 + (rng.gauss(0.0, noise_mmhg) if noise_mmhg > 0.0 else 0.0)
        patient.step(rate)
    return fit_fopdt(np.arange(n) * step_s, dy, rate)
