"""Emit the standalone Python controller module (standard library only, no import at all).

The emitted module has a float mode and a bit-exact integer mode (the C target's twin). Both run
the same algorithm (see :mod:`codegen.fixed_point` for the integer formats):

1. e = target - MAP; any non-finite input (or e) holds the last command, updates nothing and sets
   ``status.input_invalid``; e is clamped to +-E_LIM.
2. rho -> grid coordinates s_i = (rho_i - lo_i) * inv_h_i, clamped to [0, n_i - 1] (never
   extrapolated, ``rho_clamped``), then rate-limited to the synthesis bounds (``rho_rate_limited``;
   the first step after reset takes rho as is).
3. Cell i = min(int(s), n - 2), fraction s - i; 2^3 multilinear weights.
4. The current x_k is written into the ring buffer (length ceil(tau_max/Ts) + 1); x_d = x_k(t - tau)
   is read D = tau/Ts samples back, linearly interpolated between the two neighbouring samples.
5. Increment dz = M(rho) [z; x_d; e] with M interpolated over the 8 corners.
6. Anti-windup: u + du is clamped to [0, max_rate]; if it hit a limit and du pushes further into
   it, the controller states (x_k, x_e) are frozen this step (conditional integration); states are
   saturated to their Q0.31 range in both modes.
7. Return u (ml/h), clamped once more to [0, max_rate] after the unit conversion.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from codegen.fixed_point import GRID_FRAC_BITS, FixedPointPlan

__all__ = ["EmitSpec", "emit_python", "py_float"]


@dataclass(frozen=True)
class EmitSpec:
    """Everything the emitters need besides the fixed-point plan.

    Attributes
    ----------
    lo, hi, counts
        Tabulation grid (physical units: K mmHg/(ml/h), T s, tau s).
    rate_bounds
        |dK/dt| (1/s units of K), |dT/dt| (s/s), |dtau/dt| (s/s).
    sample_period_s, max_rate_ml_h
        Ts and pump limit.
    n_k
        Controller order.
    artifact_sha256, content_hash, command
        Provenance for the header.
    budgets
        Name -> (value, description) error budgets stated in the header.
    """

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    counts: tuple[int, int, int]
    rate_bounds: tuple[float, float, float]
    sample_period_s: float
    max_rate_ml_h: float
    n_k: int
    artifact_sha256: str
    content_hash: str
    command: str
    budgets: dict[str, tuple[float, str]]


def py_float(x: float) -> str:
    """Exact round-trip literal of a float."""
    return repr(float(x))


def derived_constants(spec: EmitSpec, plan: FixedPointPlan) -> dict[str, float | int]:
    """Constants shared by both emitters (so Python and C compute with the same numbers)."""
    ts = spec.sample_period_s
    inv = [(spec.counts[i] - 1) / (spec.hi[i] - spec.lo[i]) for i in range(3)]
    h_tau = (spec.hi[2] - spec.lo[2]) / (spec.counts[2] - 1)
    one_g = 1 << GRID_FRAC_BITS
    nz = spec.n_k + 2
    c: dict[str, float | int] = {
        "NBUF": int(math.ceil(spec.hi[2] / ts - 1e-9)) + 1,
        "TAU0_SAMPLES": spec.lo[2] / ts,
        "TAU_STEP_SAMPLES": h_tau / ts,
        "DMAX_SAMPLES": spec.hi[2] / ts,
        "TAU0_Q": int(round(spec.lo[2] / ts * one_g)),
        "TAU_STEP_Q16": int(round(h_tau / ts * 65536.0)),
        "DMAX_Q": int(math.floor(spec.hi[2] / ts * one_g)),
        "E_LIM": plan.e_scale,
        "E_TO_S": 1.0 / plan.e_scale,
        "E_TO_Q": 2.0**31 / plan.e_scale,
        "U_SCALE": float(plan.state_scale[spec.n_k]),
        "U_MAX_S": spec.max_rate_ml_h / float(plan.state_scale[spec.n_k]),
        "U_MAX_Q": int(math.floor(spec.max_rate_ml_h / plan.state_scale[spec.n_k] * 2.0**31)),
        "U_Q_TO_ML_H": float(plan.state_scale[spec.n_k]) / 2.0**31,
        "XE_GAIN": plan.xe_gain,
        "XE_Q": plan.xe_q,
        "XE_SHIFT": plan.xe_shift,
        "W": plan.weight_bits,
        "GONE_Q": one_g,
    }
    for i in range(3):
        c[f"LO{i}"] = float(spec.lo[i])
        c[f"HI{i}"] = float(spec.hi[i])
        c[f"INV{i}"] = float(inv[i])
        c[f"NMAX{i}"] = float(spec.counts[i] - 1)
        c[f"CMAX{i}"] = int(spec.counts[i] - 2)
        dmax = spec.rate_bounds[i] * ts * inv[i]
        c[f"DMAX{i}"] = float(dmax)
        c[f"DMAXQ{i}"] = max(1, int(math.floor(dmax * one_g)))
    for i in range(nz - 1):
        c[f"F{i}"] = int(plan.row_shift[i])
    return c


def nonzero_entries(plan: FixedPointPlan) -> list[tuple[int, int]]:
    """(row, col) of the coefficients that are non-zero at some node (others are skipped)."""
    nzmask = np.any(plan.scaled_tables != 0.0, axis=(0, 1, 2))
    return [(int(i), int(j)) for i, j in zip(*np.nonzero(nzmask), strict=True)]


def corner_offsets(counts: Sequence[int]) -> list[int]:
    """Flat-index offsets of the 8 cell corners, corner c = (cK, cT, ctau) as bits 2, 1, 0."""
    _, nt, na = counts
    return [ck * nt * na + ct * na + ca for ck in (0, 1) for ct in (0, 1) for ca in (0, 1)]


def _tables_literal(values: np.ndarray, entries: list[tuple[int, int]], fmt) -> str:
    flat = values.reshape(-1, *values.shape[3:])
    lines = []
    for node in flat:
        lines.append("    (" + ", ".join(fmt(node[i, j]) for i, j in entries) + ",),")
    return "(\n" + "\n".join(lines) + "\n)"


def _header(spec: EmitSpec, plan: FixedPointPlan) -> str:
    nk = spec.n_k
    scales = ", ".join(
        [f"x_k{i}: {plan.state_scale[i]:g}" for i in range(nk)]
        + [f"u: {plan.state_scale[nk]:g} ml/h", f"x_e: {plan.state_scale[nk + 1]:g} mmHg*s"]
    )
    budgets = "\n".join(f"    {k} = {v[0]!r}: {v[1]}" for k, v in sorted(spec.budgets.items()))
    return f'''"""LPV MAP controller generated by pressor codegen. DO NOT EDIT.

Generated with:   {spec.command}
Artifact sha256:  {spec.artifact_sha256}
Content hash:     {spec.content_hash}

Standard library only (no import). ``Controller().step(map_mmhg, target_mmhg, K, T, tau)`` returns
the infusion command in ml/h for this tick, in [0, MAX_RATE_ML_H]; ``Controller(fixed_point=True)``
runs the bit-exact integer ({plan.fmt}) data path of the generated C. Sample period
{spec.sample_period_s} s; grid {spec.counts[0]}x{spec.counts[1]}x{spec.counts[2]} over K
[{spec.lo[0]}, {spec.hi[0]}] mmHg/(ml/h), T [{spec.lo[1]}, {spec.hi[1]}] s, tau [{spec.lo[2]},
{spec.hi[2]}] s (clamped, never extrapolated; rates limited to {list(spec.rate_bounds)} per s).

Controller: z = [x_k, u (ml/h), x_e (mmHg*s)], z[k+1] = z[k] + M(rho) [z; x_k(t - tau); e],
M = [Phi - I, Gamma] the exact ZOH discretisation at each node (increment / delta form), x_k(t - tau)
from a ring buffer of NBUF samples with linear interpolation, anti-windup by conditional
integration at the pump limits [0, {spec.max_rate_ml_h}] ml/h. Non-finite input holds the last
command.

Scaling (power of two, common to all nodes): {scales}; e: {plan.e_scale:g} mmHg (clamp).
Q-formats ({plan.fmt}): states, e and x_d Q0.31 int32 (saturating); grid coordinates Q11.20;
weights Q{31 - plan.weight_bits}.{plan.weight_bits}; coefficients |q| <= 2^{plan.coef_bits}-1 with
per-row shifts {plan.row_shift.tolist()}; 64-bit accumulators; arithmetic right shifts; rounding
only on the row increment.

Error budgets (asserted by tests/test_codegen_*.py):
{budgets}
"""
'''


def emit_python(spec: EmitSpec, plan: FixedPointPlan, tables_hash: str) -> str:
    """Source text of the generated module (deterministic for equal inputs)."""
    c = derived_constants(spec, plan)
    nk = spec.n_k
    nz = nk + 2
    ncol = 2 * nk + 3
    entries = nonzero_entries(plan)
    offs = corner_offsets(spec.counts)
    W = plan.weight_bits
    out: list[str] = [_header(spec, plan)]
    add = out.append
    add(f"ARTIFACT_SHA256 = {spec.artifact_sha256!r}")
    add(f"CONTENT_HASH = {spec.content_hash!r}")
    add(f"TABLES_SHA256 = {tables_hash!r}")
    add(f"GENERATION_COMMAND = {spec.command!r}")
    add(f"SAMPLE_PERIOD_S = {py_float(spec.sample_period_s)}")
    add(f"MAX_RATE_ML_H = {py_float(spec.max_rate_ml_h)}")
    add(f"GRID_LO = ({', '.join(py_float(x) for x in spec.lo)})  # K mmHg/(ml/h), T s, tau s")
    add(f"GRID_HI = ({', '.join(py_float(x) for x in spec.hi)})")
    add(f"GRID_COUNTS = {tuple(int(x) for x in spec.counts)!r}")
    add(f"GRID_INV_SPACING = ({', '.join(py_float(c[f'INV{i}']) for i in range(3))})")
    add(f"RATE_BOUNDS = ({', '.join(py_float(x) for x in spec.rate_bounds)})  # per s")
    add(f"DELAY_BUFFER_LEN = {c['NBUF']}")
    add(f"N_K = {nk}")
    add(f"E_LIM_MMHG = {py_float(plan.e_scale)}")
    add(f"STATE_SCALE = ({', '.join(py_float(x) for x in plan.state_scale)},)")
    add(
        "Q_FORMATS = {"
        f"'format': {plan.fmt!r}, 'state': 'Q0.31', 'grid': 'Q11.20', "
        f"'weight': 'Q{31 - W}.{W}', 'coef_bits': {plan.coef_bits}, "
        f"'row_shift': {tuple(int(x) for x in plan.row_shift)!r}, 'xe_shift': {plan.xe_shift}, "
        "'accumulator': 'int64'}"
    )
    for name, (value, _) in sorted(spec.budgets.items()):
        add(f"{name} = {py_float(value)}")
    add("")
    add("_INF = float('inf')")
    add("_QMAX = 2147483647")
    for k in sorted(c):
        v = c[k]
        add(f"_{k} = {py_float(v) if isinstance(v, float) else v}")
    add("")
    add(f"_ENTRIES = {tuple(entries)!r}  # (row, col) of the stored coefficients")
    add("_TF = " + _tables_literal(plan.scaled_tables, entries, py_float))
    add("_TQ = " + _tables_literal(plan.q_tables, entries, lambda x: str(int(x))))
    add(
        '''

class ControllerStatus:
    """Flags of the last step (reused object; read, do not keep)."""

    __slots__ = ("saturated", "rho_clamped", "rho_rate_limited", "input_invalid")

    def __init__(self):
        self.saturated = False
        self.rho_clamped = False
        self.rho_rate_limited = False
        self.input_invalid = False

    def __repr__(self):
        return (
            f"ControllerStatus(saturated={self.saturated}, rho_clamped={self.rho_clamped}, "
            f"rho_rate_limited={self.rho_rate_limited}, input_invalid={self.input_invalid})"
        )


class Controller:
    """The scheduled LPV controller (runtime.controller.Controller protocol).

    Parameters
    ----------
    fixed_point
        False: float data path; True: the bit-exact integer data path of the C target.
    """

    sample_period_s = SAMPLE_PERIOD_S
    max_rate_ml_h = MAX_RATE_ML_H

    def __init__(self, fixed_point=False):
        self.fixed_point = bool(fixed_point)
        self._status = ControllerStatus()
        self.step = self._step_fixed if self.fixed_point else self._step_float
        self.reset()

    @property
    def status(self):
        """Flags of the last step (saturated, rho_clamped, rho_rate_limited, input_invalid)."""
        return self._status

    def reset(self):
        """Zero every state and the delay line; the next step takes rho without rate limit."""
        zero = 0 if self.fixed_point else 0.0
        self._z = [zero] * '''
        + str(nz)
        + '''
        self._buf = [[zero] * _NBUF for _ in range(N_K)]
        self._head = 0
        self._g = [zero, zero, zero]
        self._started = False
        self._out = 0.0
        st = self._status
        st.saturated = st.rho_clamped = st.rho_rate_limited = st.input_invalid = False

    def state(self):
        """Internal state as a tuple (z..., grid coordinates...) for tests and logging."""
        return tuple(self._z) + tuple(self._g)
'''
    )
    add(_float_step(spec, plan, entries, offs, nk, nz, ncol))
    add(_fixed_step(spec, plan, entries, offs, nk, nz, ncol))
    return "\n".join(out) + "\n"


def _rho_block(fixed: bool) -> list[str]:
    """Clamp to the grid and rate-limit; leaves g0, g1, g2 (grid coordinates)."""
    L = []
    L.append("        clamped = False")
    L.append("        limited = False")
    L.append("        g = self._g")
    for i, name in enumerate(("K", "T", "tau")):
        L.append(f"        x = ({name} - _LO{i}) * _INV{i}")
        L.append("        if x < 0.0:")
        L.append("            x = 0.0")
        L.append("            clamped = True")
        L.append(f"        elif x > _NMAX{i}:")
        L.append(f"            x = _NMAX{i}")
        L.append("            clamped = True")
        if fixed:
            L.append(f"        x = int(x * {float(1 << GRID_FRAC_BITS)!r})")
            dm = f"_DMAXQ{i}"
        else:
            dm = f"_DMAX{i}"
        L.append("        if self._started:")
        L.append(f"            p = g[{i}]")
        L.append(f"            if x > p + {dm}:")
        L.append(f"                x = p + {dm}")
        L.append("                limited = True")
        L.append(f"            elif x < p - {dm}:")
        L.append(f"                x = p - {dm}")
        L.append("                limited = True")
        L.append(f"        g{i} = x")
    L.append("        g[0] = g0")
    L.append("        g[1] = g1")
    L.append("        g[2] = g2")
    L.append("        self._started = True")
    return L


def _entry_rows(entries: list[tuple[int, int]], nz: int) -> dict[int, list[tuple[int, int]]]:
    rows: dict[int, list[tuple[int, int]]] = {i: [] for i in range(nz - 1)}
    for p, (i, j) in enumerate(entries):
        rows[i].append((p, j))
    return rows


def _common_head(fixed: bool, nk: int) -> list[str]:
    L = []
    sig = "(self, map_mmhg, target_mmhg, K, T, tau)"
    L.append(f"    def {'_step_fixed' if fixed else '_step_float'}{sig}:")
    L.append(
        '        """One sample: MAP and target in mmHg, K mmHg/(ml/h), T s, tau s -> command ml/h."""'
    )
    L.append("        st = self._status")
    L.append("        e = target_mmhg - map_mmhg")
    L.append("        if e - e != 0.0 or K - K != 0.0 or T - T != 0.0 or tau - tau != 0.0:")
    L.append("            st.input_invalid = True")
    L.append("            return self._out")
    L.append("        st.input_invalid = False")
    L.append("        if e > _E_LIM:")
    L.append("            e = _E_LIM")
    L.append("        elif e < -_E_LIM:")
    L.append("            e = -_E_LIM")
    return L


def _to_weight(name: str, w_bits: int) -> str:
    """Convert a Q.20 fraction to the weight format (shift left or right by a constant)."""
    if w_bits >= GRID_FRAC_BITS:
        return f"{name} << {w_bits - GRID_FRAC_BITS}"
    return f"{name} >> {GRID_FRAC_BITS - w_bits}"


def _corner_lines(offs: list[int], fixed: bool, w_bits: int = 0) -> list[str]:
    L = []
    one = "(1 << _W)" if fixed else "1.0"
    if fixed:
        sh = GRID_FRAC_BITS - 0
        for i, nm in enumerate("abc"):
            L.append(f"        i{i} = g{i} >> {sh}")
            L.append(f"        if i{i} > _CMAX{i}:")
            L.append(f"            i{i} = _CMAX{i}")
            L.append(f"        f{nm} = g{i} - (i{i} << {sh})")
            L.append(f"        f{nm} = {_to_weight(f'f{nm}', w_bits)}")
        L.append(f"        ga = {one} - fa")
        L.append(f"        gb = {one} - fb")
        L.append(f"        gc = {one} - fc")
        L.append("        t00 = (ga * gb) >> _W")
        L.append("        t01 = (ga * fb) >> _W")
        L.append("        t10 = (fa * gb) >> _W")
        L.append("        t11 = (fa * fb) >> _W")
        pairs = ["t00", "t01", "t10", "t11"]
        for c in range(8):
            ab = pairs[c >> 1]
            cc = "fc" if c & 1 else "gc"
            L.append(f"        w{c} = ({ab} * {cc}) >> _W")
    else:
        for i, nm in enumerate("abc"):
            L.append(f"        i{i} = int(g{i})")
            L.append(f"        if i{i} > _CMAX{i}:")
            L.append(f"            i{i} = _CMAX{i}")
            L.append(f"        f{nm} = g{i} - i{i}")
        L.append("        ga = 1.0 - fa")
        L.append("        gb = 1.0 - fb")
        L.append("        gc = 1.0 - fc")
        L.append("        t00 = ga * gb")
        L.append("        t01 = ga * fb")
        L.append("        t10 = fa * gb")
        L.append("        t11 = fa * fb")
        pairs = ["t00", "t01", "t10", "t11"]
        for c in range(8):
            L.append(f"        w{c} = {pairs[c >> 1]} * {'fc' if c & 1 else 'gc'}")
    return L


def _delay_lines(fixed: bool, nk: int, w_bits: int = 0) -> list[str]:
    L = []
    if fixed:
        L.append("        d = _TAU0_Q + ((g2 * _TAU_STEP_Q16) >> 16)")
        L.append("        if d > _DMAX_Q:")
        L.append("            d = _DMAX_Q")
        L.append(f"        n = d >> {GRID_FRAC_BITS}")
        L.append(f"        fd = d - (n << {GRID_FRAC_BITS})")
        L.append(f"        fd = {_to_weight('fd', w_bits)}")
    else:
        L.append("        d = _TAU0_SAMPLES + g2 * _TAU_STEP_SAMPLES")
        L.append("        if d > _DMAX_SAMPLES:")
        L.append("            d = _DMAX_SAMPLES")
        L.append("        n = int(d)")
        L.append("        fd = d - n")
    L.append("        z = self._z")
    L.append("        buf = self._buf")
    L.append("        h = self._head")
    L.append("        i = h - n")
    L.append("        if i < 0:")
    L.append("            i += _NBUF")
    L.append("        j = i - 1")
    L.append("        if j < 0:")
    L.append("            j += _NBUF")
    for s in range(nk):
        L.append(f"        bs = buf[{s}]")
        L.append(f"        bs[h] = z{s} = z[{s}]")
        L.append("        a = bs[i]")
        if fixed:
            L.append(f"        v{nk + 2 + s} = a + (((bs[j] - a) * fd) >> _W)")
        else:
            L.append(f"        v{nk + 2 + s} = a + (bs[j] - a) * fd")
    L.append("        h += 1")
    L.append("        if h == _NBUF:")
    L.append("            h = 0")
    L.append("        self._head = h")
    return L


def _update_lines(fixed: bool, nk: int, nz: int) -> list[str]:
    """Anti-windup, state update with saturation, output."""
    L = []
    lo, hi = ("-_QMAX", "_QMAX") if fixed else ("-1.0", "1.0")
    umax = "_U_MAX_Q" if fixed else "_U_MAX_S"
    zero = "0" if fixed else "0.0"
    L.append(f"        un = z[{nk}] + d{nk}")
    L.append("        freeze = False")
    L.append(f"        if un > {umax}:")
    L.append(f"            un = {umax}")
    L.append(f"            freeze = d{nk} > {zero}")
    L.append("            st.saturated = True")
    L.append(f"        elif un < {zero}:")
    L.append(f"            un = {zero}")
    L.append(f"            freeze = d{nk} < {zero}")
    L.append("            st.saturated = True")
    L.append("        else:")
    L.append("            st.saturated = False")
    L.append(f"        z[{nk}] = un")
    L.append("        if not freeze:")
    if fixed:
        L.append("            dxe = (v_e * _XE_Q + (1 << (_XE_SHIFT - 1))) >> _XE_SHIFT")
    else:
        L.append("            dxe = v_e * _XE_GAIN")
    targets = [(s, f"z{s} + d{s}") for s in range(nk)] + [(nk + 1, f"z[{nk + 1}] + dxe")]
    for s, expr in targets:
        L.append(f"            x = {expr}")
        L.append(f"            if x > {hi}:")
        L.append(f"                x = {hi}")
        L.append(f"            elif x < {lo}:")
        L.append(f"                x = {lo}")
        L.append(f"            z[{s}] = x")
    if fixed:
        L.append("        out = un * _U_Q_TO_ML_H")
    else:
        L.append("        out = un * _U_SCALE")
    L.append("        if out > MAX_RATE_ML_H:")
    L.append("            out = MAX_RATE_ML_H")
    L.append("        elif out < 0.0:")
    L.append("            out = 0.0")
    L.append("        self._out = out")
    L.append("        st.rho_clamped = clamped")
    L.append("        st.rho_rate_limited = limited")
    L.append("        return out")
    return L


def _float_step(spec, plan, entries, offs, nk, nz, ncol) -> str:
    L = _common_head(False, nk)
    L.append("        v_e = e * _E_TO_S")
    L += _rho_block(False)
    L += _corner_lines(offs, False)
    L += _delay_lines(False, nk)
    # v0..v{nz-1} are z, v{nz}.. x_d, v{nz+nk} = e; z_s for s < nk already bound above.
    for s in range(nk, nz):
        L.append(f"        v{s} = z[{s}]")
    for s in range(nk):
        L.append(f"        v{s} = z{s}")
    L.append(f"        v{nz + nk} = v_e")
    rows = _entry_rows(entries, nz)
    L.append(f"        b = (i0 * {spec.counts[1]} + i1) * {spec.counts[2]} + i2")
    L.append("        t = _TF")
    for r in range(nz - 1):
        L.append(f"        d{r} = 0.0")
    names = ", ".join(f"m{p}" for p in range(len(entries)))
    for ci, off in enumerate(offs):
        L.append(f"        {names}, = t[b + {off}]")
        for r in range(nz - 1):
            if rows[r]:
                expr = " + ".join(f"m{p} * v{j}" for p, j in rows[r])
                L.append(f"        d{r} += w{ci} * ({expr})")
    L += _update_lines(False, nk, nz)
    return "\n".join(L) + "\n"


def _fixed_step(spec, plan, entries, offs, nk, nz, ncol) -> str:
    L = _common_head(True, nk)
    L.append("        v_e = int(e * _E_TO_Q)")
    L.append("        if v_e > _QMAX:")
    L.append("            v_e = _QMAX")
    L.append("        elif v_e < -_QMAX:")
    L.append("            v_e = -_QMAX")
    L += _rho_block(True)
    L += _corner_lines(offs, True, plan.weight_bits)
    L += _delay_lines(True, nk, plan.weight_bits)
    for s in range(nk, nz):
        L.append(f"        v{s} = z[{s}]")
    for s in range(nk):
        L.append(f"        v{s} = z{s}")
    L.append(f"        v{nz + nk} = v_e")
    L.append(f"        b = (i0 * {spec.counts[1]} + i1) * {spec.counts[2]} + i2")
    L.append("        t = _TQ")
    for ci, off in enumerate(offs):
        L.append(f"        c{ci} = t[b + {off}]")
    rows = _entry_rows(entries, nz)
    for r in range(nz - 1):
        terms = []
        for p, j in rows[r]:
            interp = " + ".join(f"w{ci} * c{ci}[{p}]" for ci in range(8))
            L.append(f"        m = ({interp}) >> _W")
            terms.append(f"m * v{j}")
            L.append(f"        a{r}_{p} = m * v{j}")
        acc = " + ".join(f"a{r}_{p}" for p, _ in rows[r]) or "0"
        L.append(f"        d{r} = ({acc} + (1 << (_F{r} - 1))) >> _F{r}")
    L += _update_lines(True, nk, nz)
    return "\n".join(L) + "\n"
