"""Q-format choice, state scaling and coefficient quantisation (CMSIS-DSP conventions).

Scaling (one common diagonal scaling for every node). Each state and input is divided by a power of
two ``S`` so its scaled value lies in [-1, 1): ``z~ = z / S_z``, ``e~ = e / S_e``. ``S`` comes from the
ranges the signals actually take: the sampled closed loop is simulated at every box corner and the
centre (frozen rho, the patient K/(Ts+1)e^(-tau s), pump limits [0, max_rate] with the same
anti-windup as the generated step) for a +R mmHg target step followed by a -R mmHg step; the peak
of each state times ``headroom`` (4 = 2 guard bits) is rounded up to a power of two. The MAP error is
clamped to +-E_LIM (128 mmHg, so S_e = 128) before scaling. The scaled increment matrix is
``M~_ij = M_ij * S_col_j / S_row_i``.

Fixed-point data path (integer mode; Python and C identical bit for bit):

============  ==========================  ========================================================
quantity      storage                     format
============  ==========================  ========================================================
states z~     int32                       Q0.31 (value = q / 2^31), saturating to +-(2^31 - 1)
e~, x_d~      int32                       Q0.31
rho (grid)    int32                       Q11.20 grid coordinates, s = (rho - lo) / h
weights       int32                       Q1.30 (q31) / Q1.15 (q15), sum <= 1
coefficients  int32 (q31) / int16 (q15)   row i: value = q / 2^F_i, |q| <= 2^27-1 / 2^15-1
interp. acc.  int64                       sum_c w_c q_c  (<= 2^57 / 2^30), then >> 30 / >> 15
row acc.      int64                       sum_j m_ij v_j (9 terms: < 2^62 / 2^50), then
                                          rounding shift >> F_i to Q0.31
============  ==========================  ========================================================

Shifts are arithmetic (floor) right shifts of signed integers (Python ``>>``; C ``>>`` on signed
values, which gcc defines as arithmetic — the C header asserts it at compile time). The only
rounding is the row increment: ``(acc + 2^(F_i-1)) >> F_i``. Saturation happens on the state
update, on the input conversion and on the pump clamp. The q15 variant keeps Q0.31 states (as
CMSIS's 32x64 biquads do): a Q15 state would give a 2^-15 full-scale step and stall the slow
integrating modes, so only the coefficients and weights are 16-bit.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pressor.synthesis.verification.discrete_step import sampled_fopdt

__all__ = [
    "E_LIM_MMHG",
    "FixedPointPlan",
    "FORMATS",
    "make_plan",
    "signal_peaks",
]

Matrix = NDArray[np.float64]

#: MAP error clamp (mmHg); also the error scale S_e.
E_LIM_MMHG = 128.0
#: (coefficient magnitude bits, weight fraction bits) per format.
FORMATS: dict[str, tuple[int, int]] = {"q31": (27, 30), "q15": (15, 15)}


def _pow2_ceil(x: float) -> float:
    return float(2.0 ** math.ceil(math.log2(x))) if x > 0 else 1.0


def signal_peaks(
    tables: Matrix,
    box: Matrix,
    sample_period_s: float,
    max_rate_ml_h: float,
    step_mmhg: float = 40.0,
    duration_s: float = 3600.0,
    report: Callable[[str, int, int], None] | None = None,
) -> Matrix:
    """Peak |z_i| (physical units) over frozen closed-loop runs at the box corners and centre.

    The tables' corner nodes are the box corners; the centre uses the node nearest the centre.
    Scenario: target +``step_mmhg`` at t = 0, back down at ``duration_s``/2; the pump clamps to
    [0, max_rate_ml_h] with the generated step's anti-windup (controller update frozen while the
    command is pinned at a limit and its increment pushes further into it). The patient is the
    first-order-plus-delay model sampled exactly
    (:func:`pressor.synthesis.verification.discrete_step.sampled_fopdt`).
    ``report(what, t, duration_s)`` is called every simulated minute (whole seconds).
    """
    nk_, nt_, na_ = tables.shape[:3]
    idx = [(i, j, k) for i in (0, nk_ - 1) for j in (0, nt_ - 1) for k in (0, na_ - 1)]
    idx.append((nk_ // 2, nt_ // 2, na_ // 2))
    axes = [np.linspace(box[i, 0], box[i, 1], tables.shape[i]) for i in range(3)]
    mats = np.stack([tables[i, j, k] for i, j, k in idx])
    rhos = np.array([[axes[0][i], axes[1][j], axes[2][k]] for i, j, k in idx])
    b = len(idx)
    nz = tables.shape[3]
    nk = nz - 2
    ts = sample_period_s
    d = rhos[:, 2] / ts
    n = np.floor(d).astype(int)
    f = d - n
    plants = [sampled_fopdt(*rho, ts) for rho in rhos]
    a = np.array([p.a for p in plants])
    b_new = np.array([p.b_new for p in plants])  # weight of c_{k-W}
    b_old = np.array([p.b_old for p in plants])  # weight of c_{k-W-1}
    w = np.array([p.whole for p in plants])
    nbuf = int(max(n.max(), w.max())) + 3
    steps = int(round(duration_s / ts))
    xbuf = np.zeros((nbuf, b, nk))
    cbuf = np.zeros((nbuf, b))
    z = np.zeros((b, nz))
    dmap = np.zeros(b)
    peaks = np.zeros(nz)
    ar = np.arange(b)
    per_minute = max(1, int(round(60.0 / ts)))
    for k in range(steps):
        r = step_mmhg if k < steps // 2 else 0.0
        e = np.clip(r - dmap, -E_LIM_MMHG, E_LIM_MMHG)
        h = k % nbuf
        xbuf[h] = z[:, :nk]
        xd = (1 - f)[:, None] * xbuf[(h - n) % nbuf, ar] + f[:, None] * xbuf[(h - n - 1) % nbuf, ar]
        v = np.concatenate([z, xd, e[:, None]], axis=1)
        dz = np.einsum("bij,bj->bi", mats, v)
        un = z[:, nk] + dz[:, nk]
        hi = un > max_rate_ml_h
        lo = un < 0.0
        freeze = (hi & (dz[:, nk] > 0)) | (lo & (dz[:, nk] < 0))
        upd = ~freeze
        z[upd, :nk] += dz[upd, :nk]
        z[upd, nk + 1] += dz[upd, nk + 1]
        z[:, nk] = np.clip(un, 0.0, max_rate_ml_h)
        cbuf[h] = z[:, nk]
        dmap = a * dmap + b_new * cbuf[(h - w) % nbuf, ar] + b_old * cbuf[(h - w - 1) % nbuf, ar]
        np.maximum(peaks, np.max(np.abs(z), axis=0), out=peaks)
        if report is not None and (k + 1) % per_minute == 0:
            report("scaling runs, seconds simulated", int(round((k + 1) * ts)), int(duration_s))
    return peaks


@dataclass(frozen=True)
class FixedPointPlan:
    """Scalings, Q-formats and quantised tables for one tabulated design.

    Attributes
    ----------
    fmt
        "q31" or "q15" (coefficient/weight width; states are Q0.31 in both).
    coef_bits, weight_bits
        |q| <= 2^coef_bits - 1; weights in Q(weight_bits).
    state_scale
        S_z per state [x_k..., u (ml/h), x_e (mmHg*s)], powers of two.
    e_scale
        S_e (mmHg), = E_LIM_MMHG.
    scaled_tables
        (nK, nT, ntau, n_z - 1, n_col) float increment matrices in scaled coordinates, x_e row
        dropped (it is the constant ``xe_gain``).
    row_shift
        F_i per tabulated row.
    q_tables
        Integer mantissas of ``scaled_tables`` (``round(M~ * 2^F_i)``), int64 array.
    xe_gain, xe_q, xe_shift
        x_e increment per unit e~: Ts*S_e/S_xe, its mantissa and shift.
    peaks
        Simulated peaks |z_i| (physical units) the scaling was chosen from.
    headroom
        Factor between the simulated peak and the scale (before power-of-two rounding).
    """

    fmt: str
    coef_bits: int
    weight_bits: int
    state_scale: Matrix
    e_scale: float
    scaled_tables: Matrix
    row_shift: NDArray[np.int64]
    q_tables: NDArray[np.int64]
    xe_gain: float
    xe_q: int
    xe_shift: int
    peaks: Matrix
    headroom: float


def make_plan(
    tables: Matrix,
    box: Matrix,
    sample_period_s: float,
    max_rate_ml_h: float,
    fmt: str = "q31",
    headroom: float = 4.0,
    report: Callable[[str, int, int], None] | None = None,
) -> FixedPointPlan:
    """Choose the state scaling and Q-formats and quantise ``tables`` (see the module docstring).

    ``report`` receives the progress of the scaling simulation (:func:`signal_peaks`).

    Raises
    ------
    ValueError
        Unknown ``fmt``, or a coefficient that cannot be represented with a positive shift.
    """
    if fmt not in FORMATS:
        raise ValueError(f"fixed-point format {fmt!r}: expected one of {sorted(FORMATS)}")
    coef_bits, weight_bits = FORMATS[fmt]
    box = np.asarray(box, float)
    nz = tables.shape[3]
    nk = nz - 2
    peaks = signal_peaks(tables, box, sample_period_s, max_rate_ml_h, report=report)
    peaks[nk] = max(peaks[nk], max_rate_ml_h)  # u spans the whole pump range by construction
    scale = np.array([_pow2_ceil(headroom * p) for p in peaks])
    col_scale = np.concatenate([scale, scale[:nk], [E_LIM_MMHG]])
    scaled = tables * col_scale[None, None, None, None, :] / scale[None, None, None, :, None]
    scaled = scaled[..., : nz - 1, :]
    qmax = 2**coef_bits - 1
    row_max = np.max(np.abs(scaled), axis=(0, 1, 2, 4))
    shifts = np.array(
        [int(math.floor(math.log2(qmax / m))) if m > 0 else 1 for m in row_max], dtype=np.int64
    )
    if np.any(shifts < 1) or np.any(shifts > 62):
        raise ValueError(f"row shifts {shifts.tolist()} outside [1, 62]; rescale the design")
    q = np.rint(scaled * (2.0 ** shifts.astype(float))[None, None, None, :, None]).astype(np.int64)
    assert np.max(np.abs(q)) <= qmax
    xe_gain = sample_period_s * E_LIM_MMHG / scale[nz - 1]
    xe_shift = int(math.floor(math.log2(qmax / xe_gain)))
    xe_q = int(round(xe_gain * 2.0**xe_shift))
    return FixedPointPlan(
        fmt=fmt,
        coef_bits=coef_bits,
        weight_bits=weight_bits,
        state_scale=scale,
        e_scale=E_LIM_MMHG,
        scaled_tables=scaled,
        row_shift=shifts,
        q_tables=q,
        xe_gain=float(xe_gain),
        xe_q=xe_q,
        xe_shift=xe_shift,
        peaks=peaks,
        headroom=headroom,
    )
