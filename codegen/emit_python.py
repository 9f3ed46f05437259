"""Emit the standalone Python controller module (standard library only, no import at all).

The emitted module has a float mode and a bit-exact integer mode (the C target's twin). Both run
the same algorithm (see :mod:`codegen.fixed_point` for the integer formats):

1. e = target - MAP; any non-finite input (or e) holds the last command, updates nothing and sets
   ``status.input_invalid``. With the design's two-degree-of-freedom prefilter
   (:mod:`synthesis.reference`, emitted only when the artifact enables it) e = r_m - MAP instead,
   r_m and the feedforward u_ff from the scheduled model, in double in both modes. e is clamped to
   +-E_LIM.
2. rho -> grid coordinates s_i = (rho_i - lo_i) * inv_h_i, clamped to [0, n_i - 1] (never
   extrapolated, ``rho_clamped``), then rate-limited to the synthesis bounds (``rho_rate_limited``;
   the first step after reset takes rho as is).
3. Cell i = min(int(s), n - 2), fraction s - i; 2^3 multilinear weights.
4. The current x_k is written into the ring buffer (length ceil(tau_max/Ts) + 1); x_d = x_k(t - tau)
   is read D = tau/Ts samples back, linearly interpolated between the two neighbouring samples.
5. Increment dz = M(rho) [z; x_d; e] with M interpolated over the 8 corners.
6. Anti-windup: u + du is clamped to [0, max_rate]; while u sits at a limit and the error drives
   further into it (e > 0 at the upper limit, e < 0 at zero), the controller states (x_k, x_e) are
   frozen this step (conditional integration); states are saturated to their Q0.31 range in both
   modes. The freeze is keyed on the sign of e, not of du: keyed on du, a design whose u_a starts
   negative after a target step (u pinned at 0, du < 0) froze x_e for good and never infused.
   With the prefilter, u is the feedback share, clamped to [-u_ff, max_rate - u_ff], so the same
   rule freezes the feedback while the total command sits at a limit.
7. Return u (+ u_ff) in ml/h, clamped once more to [0, max_rate] after the unit conversion.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from codegen.fixed_point import FixedPointPlan
from contracts.module_hash import MODULE_SHA_PREFIX, module_text_sha256

__all__ = ["EmitSpec", "emit_python", "module_sha256", "py_float"]

# One definition of the self-hash, shared with the loader that checks it (runtime needs no codegen).
module_sha256 = module_text_sha256


@dataclass(frozen=True)
class EmitSpec:
    """Everything the emitters need besides the fixed-point plan.

    Attributes
    ----------
    nodes
        Tabulation grid nodes per axis, sorted, possibly non-uniform (physical units: K
        mmHg/(ml/h), T s, tau s).
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
    reference
        (lambda_s, pump_fraction, k_min) of the two-degree-of-freedom prefilter
        (:mod:`synthesis.reference`), or None: the controller then sees the target directly.
    """

    nodes: tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]
    rate_bounds: tuple[float, float, float]
    sample_period_s: float
    max_rate_ml_h: float
    n_k: int
    artifact_sha256: str
    content_hash: str
    command: str
    budgets: dict[str, tuple[float, str]]
    reference: tuple[float, float, float] | None = None

    @property
    def lo(self) -> tuple[float, float, float]:
        """Lower box corner."""
        return tuple(ax[0] for ax in self.nodes)  # type: ignore[return-value]

    @property
    def hi(self) -> tuple[float, float, float]:
        """Upper box corner."""
        return tuple(ax[-1] for ax in self.nodes)  # type: ignore[return-value]

    @property
    def counts(self) -> tuple[int, int, int]:
        """Nodes per axis."""
        return tuple(len(ax) for ax in self.nodes)  # type: ignore[return-value]

    def inv_widths(self, axis: int) -> list[float]:
        """Reciprocal cell widths of ``axis`` (computed once, offline)."""
        ax = self.nodes[axis]
        return [1.0 / (ax[j + 1] - ax[j]) for j in range(len(ax) - 1)]


def py_float(x: float) -> str:
    """Exact round-trip literal of a float."""
    return repr(float(x))


def derived_constants(spec: EmitSpec, plan: FixedPointPlan) -> dict[str, float | int]:
    """Constants shared by both emitters (so Python and C compute with the same numbers)."""
    ts = spec.sample_period_s
    nz = spec.n_k + 2
    c: dict[str, float | int] = {
        "NBUF": int(math.ceil(spec.hi[2] / ts - 1e-9)) + 1,
        "INV_TS": 1.0 / ts,
        "DMAX_SAMPLES": spec.hi[2] / ts,
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
        "WONE": float(1 << plan.weight_bits),
    }
    for i in range(3):
        c[f"LO{i}"] = float(spec.lo[i])
        c[f"HI{i}"] = float(spec.hi[i])
        c[f"N{i}"] = int(spec.counts[i])
        c[f"RSTEP{i}"] = float(spec.rate_bounds[i] * ts)
    for i in range(nz - 1):
        c[f"F{i}"] = int(plan.row_shift[i])
    if spec.reference is not None:
        lam, frac, k_min = spec.reference
        c["PF_KLO"] = float(k_min)
        c["PF_INV_LAMBDA"] = 1.0 / lam
        c["PF_UMAX"] = frac * spec.max_rate_ml_h
        c["PF_TS"] = float(ts)
        c["PF_SIXTH"] = 1.0 / 6.0
        c["INV_U_SCALE"] = 1.0 / float(plan.state_scale[spec.n_k])
        c["U_TO_Q"] = 2.0**31 / float(plan.state_scale[spec.n_k])
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

Scheduling (GRID_NODES): a non-uniform tensor grid in *physical* rho. The K nodes start geometric
(uniform in log K: the controller inverts the plant gain and varies roughly like 1/K) and every
axis interval is bisected where interpolation was too inaccurate or a frozen loop unstable. Per
step, in double in both modes: clamp rho to the box, limit its change to RATE_BOUNDS * Ts (physical
units), find the cell by a bounded binary search (<= ceil(log2(n - 1)) compares per axis), fraction
= (rho - node) * stored reciprocal width (no division); multilinear weights over the 2^3 corners.
The integer mode quantises the fractions to the weight format; the controller data path is integer.

Controller: z = [x_k, u (ml/h), x_e (mmHg*s)], z[k+1] = z[k] + M(rho) [z; x_k(t - tau); e],
M = [Phi - I, Gamma] the exact ZOH discretisation at each node (increment / delta form), x_k(t - tau)
from a ring buffer of NBUF samples with linear interpolation, anti-windup by conditional
integration at the pump limits [0, {spec.max_rate_ml_h}] ml/h. Non-finite input holds the last
command.

{_reference_doc(spec)}Scaling (power of two, common to all nodes): {scales}; e: {plan.e_scale:g} mmHg (clamp).
Q-formats ({plan.fmt}): states, e and x_d Q0.31 int32 (saturating); grid coordinates Q11.20;
weights Q{31 - plan.weight_bits}.{plan.weight_bits}; coefficients |q| <= 2^{plan.coef_bits}-1 with
per-row shifts {plan.row_shift.tolist()}; 64-bit accumulators; arithmetic right shifts; rounding
only on the row increment.

Error budgets (asserted by tests/test_codegen_*.py):
{budgets}
"""
'''


def _reference_doc(spec: EmitSpec) -> str:
    """Header paragraph on the prefilter (empty when the design has none)."""
    if spec.reference is None:
        return ""
    lam, frac, k_min = spec.reference
    return f"""Two degrees of freedom (synthesis.reference; lambda {lam!r} s, pump fraction {frac!r},
K floor {k_min!r} mmHg/(ml/h)): a scheduled first-order-plus-delay model anchored at the first valid
MAP after reset generates the reference MAP r_m and the feedforward
u_ff = clamp((p + T (dr - p) / lambda) / K, 0, cap), with p = y0 + y_m - y0(t - tau) (Smith
prediction), dr = target - anchor and cap = max(fraction * MAX_RATE_ML_H, min(MAX_RATE_ML_H,
dr / K)). The model runs on K clamped to [K floor, box upper K] and T, tau clamped to the box (not
rate limited), in double in both modes (two divisions, by the clamped K and T). The controller
above regulates e = r_m - MAP; its command state is clamped to [-u_ff, MAX_RATE_ML_H - u_ff]
(conditional integration against the total) and the output is u_fb + u_ff.

"""


def emit_python(spec: EmitSpec, plan: FixedPointPlan, tables_hash: str) -> str:
    """Source text of the generated module (deterministic for equal inputs)."""
    c = derived_constants(spec, plan)
    nk = spec.n_k
    nz = nk + 2
    entries = nonzero_entries(plan)
    offs = corner_offsets(spec.counts)
    W = plan.weight_bits
    out: list[str] = [_header(spec, plan)]
    add = out.append
    add(MODULE_SHA_PREFIX + "''  # sha256 of this file with this value blanked (tamper check)")
    add(f"ARTIFACT_SHA256 = {spec.artifact_sha256!r}")
    add(f"CONTENT_HASH = {spec.content_hash!r}")
    add(f"TABLES_SHA256 = {tables_hash!r}")
    add(f"GENERATION_COMMAND = {spec.command!r}")
    add(f"SAMPLE_PERIOD_S = {py_float(spec.sample_period_s)}")
    add(f"MAX_RATE_ML_H = {py_float(spec.max_rate_ml_h)}")
    add(f"GRID_LO = ({', '.join(py_float(x) for x in spec.lo)})  # K mmHg/(ml/h), T s, tau s")
    add(f"GRID_HI = ({', '.join(py_float(x) for x in spec.hi)})")
    add(f"GRID_COUNTS = {tuple(int(x) for x in spec.counts)!r}")
    add(
        "GRID_NODES = ("
        + ", ".join("(" + ", ".join(py_float(x) for x in ax) + ",)" for ax in spec.nodes)
        + ")  # physical K, T, tau nodes"
    )
    for i in range(3):
        add(f"_NODES{i} = GRID_NODES[{i}]")
        add(f"_INVW{i} = ({', '.join(py_float(x) for x in spec.inv_widths(i))},)  # 1/width")
    add(f"RATE_BOUNDS = ({', '.join(py_float(x) for x in spec.rate_bounds)})  # per s")
    add(f"REFERENCE_ENABLED = {spec.reference is not None}")
    if spec.reference is not None:
        add(f"REFERENCE_LAMBDA_S = {py_float(spec.reference[0])}")
        add(f"REFERENCE_PUMP_FRACTION = {py_float(spec.reference[1])}")
        add(f"REFERENCE_K_MIN = {py_float(spec.reference[2])}  # mmHg/(ml/h)")
    add(f"DELAY_BUFFER_LEN = {c['NBUF']}")
    add(f"N_K = {nk}")
    add(f"E_LIM_MMHG = {py_float(plan.e_scale)}")
    add(f"STATE_SCALE = ({', '.join(py_float(x) for x in plan.state_scale)},)")
    add(
        "Q_FORMATS = {"
        f"'format': {plan.fmt!r}, 'state': 'Q0.31', 'grid': 'double (clamp, rate limit, cell search)', "
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
    """The scheduled LPV controller (contracts.controller.Controller protocol).

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
        + """
        self._buf = [[zero] * _NBUF for _ in range(N_K)]
        self._head = 0
        self._r = [0.0, 0.0, 0.0]
        self._started = False
        self._out = 0.0
        st = self._status
        st.saturated = st.rho_clamped = st.rho_rate_limited = st.input_invalid = False
"""
        + _reset_reference(spec)
        + '''
    def state(self):
        """Internal state as a tuple (z..., scheduled rho K, T, tau) for tests and logging."""
        return tuple(self._z) + tuple(self._r)
'''
        + _reference_accessor(spec)
    )
    add(_float_step(spec, entries, offs, nk, nz))
    add(_fixed_step(spec, entries, offs, nk, nz))
    text = "\n".join(out) + "\n"
    digest = module_sha256(text)
    return text.replace(MODULE_SHA_PREFIX + "''", f"{MODULE_SHA_PREFIX}{digest!r}", 1)


def _reset_reference(spec: EmitSpec) -> str:
    if spec.reference is None:
        return ""
    return """        self._anchored = False
        self._m0 = 0.0
        self._y0 = 0.0
        self._ym = 0.0
        self._pbuf = [0.0] * _NBUF
        self._qbuf = [0.0] * _NBUF
        self._phead = 0
        self._rm = 0.0
        self._uff = 0.0
"""


def _reference_accessor(spec: EmitSpec) -> str:
    if spec.reference is None:
        return ""
    return '''
    def reference(self):
        """(anchor MAP mmHg, reference MAP r_m mmHg, feedforward u_ff ml/h) of the last step."""
        return (self._m0, self._rm, self._uff)
'''


def _clamp_lines(var: str, src: str, i: int, lo: str = "") -> list[str]:
    lo = lo or f"_LO{i}"
    indent = "        "
    return [
        f"{indent}{var} = {src}",
        f"{indent}if {var} < {lo}:",
        f"{indent}    {var} = {lo}",
        f"{indent}elif {var} > _HI{i}:",
        f"{indent}    {var} = _HI{i}",
    ]


def _reference_lines() -> list[str]:
    """The prefilter (synthesis.reference), in double in both modes; sets e = r_m - MAP, uff."""
    L = []
    L.append("        if not self._anchored:")
    L.append("            self._m0 = map_mmhg")
    L.append("            self._anchored = True")
    L.append("        m0 = self._m0")
    L.append("        rr = target_mmhg - m0")
    L += _clamp_lines("kp", "K", 0, lo="_PF_KLO")
    L += _clamp_lines("tp", "T", 1)
    L += _clamp_lines("dp", "tau", 2)
    L.append("        ik = 1.0 / kp")
    L.append("        y0 = self._y0")
    L.append("        ym = self._ym")
    L.append("        dp = dp * _INV_TS")
    L.append("        n = int(dp)")
    L.append("        fd = dp - n")
    L.append("        ph = self._phead")
    L.append("        i = ph - n")
    L.append("        if i < 0:")
    L.append("            i += _NBUF")
    L.append("        j = i - 1")
    L.append("        if j < 0:")
    L.append("            j += _NBUF")
    L.append("        qb = self._qbuf")
    L.append("        qb[ph] = y0")
    L.append("        a = qb[i]")
    L.append("        pr = y0 + (ym - (a + (qb[j] - a) * fd))  # Smith correction for a moving tau")
    L.append("        uff = (pr + tp * (rr - pr) * _PF_INV_LAMBDA) * ik")
    L.append("        cap = _PF_UMAX")
    L.append("        need = rr * ik")
    L.append("        if need > cap:")
    L.append("            cap = MAX_RATE_ML_H if need > MAX_RATE_ML_H else need")
    L.append("        if uff > cap:")
    L.append("            uff = cap")
    L.append("        elif uff < 0.0:")
    L.append("            uff = 0.0")
    L.append("        hs = _PF_TS / tp")
    L.append("        cs = hs * (1.0 - hs * (0.5 - hs * _PF_SIXTH))  # 1 - exp(-Ts/T)")
    L.append("        self._y0 = y0 + cs * (kp * uff - y0)")
    L.append("        pb = self._pbuf")
    L.append("        pb[ph] = uff")
    L.append("        a = pb[i]")
    L.append("        ud = a + (pb[j] - a) * fd")
    L.append("        ph += 1")
    L.append("        if ph == _NBUF:")
    L.append("            ph = 0")
    L.append("        self._phead = ph")
    L.append("        self._ym = ym + cs * (kp * ud - ym)")
    L.append("        rm = m0 + ym")
    L.append("        self._rm = rm")
    L.append("        self._uff = uff")
    L.append("        e = rm - map_mmhg")
    return L


def _rho_block(fixed: bool) -> list[str]:
    """Clamp and rate-limit physical rho, locate the cell; leaves i0..i2 and fa, fb, fc, and x2 = tau
    (fractions in [0, 1] as floats, or quantised to the weight format in integer mode)."""
    L = []
    L.append("        clamped = False")
    L.append("        limited = False")
    L.append("        r = self._r")
    L.append("        started = self._started")
    for i, (name, fr) in enumerate((("K", "fa"), ("T", "fb"), ("tau", "fc"))):
        L.append(f"        x = {name}")
        L.append(f"        if x < _LO{i}:")
        L.append(f"            x = _LO{i}")
        L.append("            clamped = True")
        L.append(f"        elif x > _HI{i}:")
        L.append(f"            x = _HI{i}")
        L.append("            clamped = True")
        L.append("        if started:")
        L.append(f"            p = r[{i}]")
        L.append(f"            if x > p + _RSTEP{i}:")
        L.append(f"                x = p + _RSTEP{i}")
        L.append("                limited = True")
        L.append(f"            elif x < p - _RSTEP{i}:")
        L.append(f"                x = p - _RSTEP{i}")
        L.append("                limited = True")
        L.append(f"        r[{i}] = x")
        L.append("        lo = 0")
        L.append(f"        hi = _N{i} - 1")
        L.append(f"        nodes = _NODES{i}")
        L.append("        while hi - lo > 1:")
        L.append("            mid = (lo + hi) >> 1")
        L.append("            if x >= nodes[mid]:")
        L.append("                lo = mid")
        L.append("            else:")
        L.append("                hi = mid")
        L.append(f"        i{i} = lo")
        L.append(f"        {fr} = (x - nodes[lo]) * _INVW{i}[lo]")
        L.append(f"        if {fr} > 1.0:")
        L.append(f"            {fr} = 1.0")
        L.append(f"        elif {fr} < 0.0:")
        L.append(f"            {fr} = 0.0")
        if fixed:
            L.append(f"        {fr} = int({fr} * _WONE)")
        if i == 2:
            L.append("        x2 = x")
    L.append("        self._started = True")
    return L


def _entry_rows(entries: list[tuple[int, int]], nz: int) -> dict[int, list[tuple[int, int]]]:
    rows: dict[int, list[tuple[int, int]]] = {i: [] for i in range(nz - 1)}
    for p, (i, j) in enumerate(entries):
        rows[i].append((p, j))
    return rows


def _common_head(fixed: bool, reference: bool) -> list[str]:
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
    if reference:
        L += _reference_lines()
    L.append("        if e > _E_LIM:")
    L.append("            e = _E_LIM")
    L.append("        elif e < -_E_LIM:")
    L.append("            e = -_E_LIM")
    return L


def _corner_lines(fixed: bool) -> list[str]:
    """2^3 multilinear weights w0..w7 (corner c = (cK, cT, ctau) as bits 2, 1, 0)."""
    L = []
    if fixed:
        L.append("        ga = (1 << _W) - fa")
        L.append("        gb = (1 << _W) - fb")
        L.append("        gc = (1 << _W) - fc")
        L.append("        t00 = (ga * gb) >> _W")
        L.append("        t01 = (ga * fb) >> _W")
        L.append("        t10 = (fa * gb) >> _W")
        L.append("        t11 = (fa * fb) >> _W")
        pairs = ["t00", "t01", "t10", "t11"]
        for c in range(8):
            L.append(f"        w{c} = ({pairs[c >> 1]} * {'fc' if c & 1 else 'gc'}) >> _W")
    else:
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


def _delay_lines(fixed: bool, nk: int) -> list[str]:
    """Ring-buffer write and fractional-delay read of x_k(t - tau), tau the scheduled value."""
    L = []
    L.append("        d = x2 * _INV_TS")
    L.append("        if d > _DMAX_SAMPLES:")
    L.append("            d = _DMAX_SAMPLES")
    L.append("        n = int(d)")
    if fixed:
        L.append("        fd = int((d - n) * _WONE)")
    else:
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
    # v0..v{nz-1} are z, v{nz}.. x_d, v{nz+nk} = e; z_s for s < nk already bound above.
    nz = nk + 2
    for s in range(nk, nz):
        L.append(f"        v{s} = z[{s}]")
    for s in range(nk):
        L.append(f"        v{s} = z{s}")
    L.append(f"        v{nz + nk} = v_e")
    return L


def _update_lines(fixed: bool, nk: int, reference: bool) -> list[str]:
    """Anti-windup, state update with saturation, output. With the prefilter the command state is
    the feedback share, clamped so that feedback + feedforward stays in [0, max_rate]."""
    L = []
    lo, hi = ("-_QMAX", "_QMAX") if fixed else ("-1.0", "1.0")
    umax = "_U_MAX_Q" if fixed else "_U_MAX_S"
    zero = "0" if fixed else "0.0"
    ulo = zero
    if reference:
        if fixed:
            L.append("        uffs = int(uff * _U_TO_Q)")
        else:
            L.append("        uffs = uff * _INV_U_SCALE")
        L.append(f"        uhi = {umax} - uffs")
        umax, ulo = "uhi", "-uffs"
    L.append(f"        un = z[{nk}] + d{nk}")
    L.append("        freeze = False")
    L.append(f"        if un > {umax}:")
    L.append(f"            un = {umax}")
    L.append(f"            freeze = v_e > {zero}")
    L.append("            st.saturated = True")
    L.append(f"        elif un < {ulo}:")
    L.append(f"            un = {ulo}")
    L.append(f"            freeze = v_e < {zero}")
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
    total = "(un + uffs)" if reference else "un"
    if fixed:
        L.append(f"        out = {total} * _U_Q_TO_ML_H")
    else:
        L.append(f"        out = {total} * _U_SCALE")
    L.append("        if out > MAX_RATE_ML_H:")
    L.append("            out = MAX_RATE_ML_H")
    L.append("        elif out < 0.0:")
    L.append("            out = 0.0")
    L.append("        self._out = out")
    L.append("        st.rho_clamped = clamped")
    L.append("        st.rho_rate_limited = limited")
    L.append("        return out")
    return L


def _float_step(spec, entries, offs, nk, nz) -> str:
    L = _common_head(False, spec.reference is not None)
    L.append("        v_e = e * _E_TO_S")
    L += _rho_block(False)
    L += _corner_lines(False)
    L += _delay_lines(False, nk)
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
    L += _update_lines(False, nk, spec.reference is not None)
    return "\n".join(L) + "\n"


def _fixed_step(spec, entries, offs, nk, nz) -> str:
    L = _common_head(True, spec.reference is not None)
    L.append("        v_e = int(e * _E_TO_Q)")
    L.append("        if v_e > _QMAX:")
    L.append("            v_e = _QMAX")
    L.append("        elif v_e < -_QMAX:")
    L.append("            v_e = -_QMAX")
    L += _rho_block(True)
    L += _corner_lines(True)
    L += _delay_lines(True, nk)
    L.append(f"        b = (i0 * {spec.counts[1]} + i1) * {spec.counts[2]} + i2")
    L.append("        t = _TQ")
    for ci, off in enumerate(offs):
        L.append(f"        c{ci} = t[b + {off}]")
    rows = _entry_rows(entries, nz)
    for r in range(nz - 1):
        for p, j in rows[r]:
            interp = " + ".join(f"w{ci} * c{ci}[{p}]" for ci in range(8))
            L.append(f"        m = ({interp}) >> _W")
            L.append(f"        a{r}_{p} = m * v{j}")
        acc = " + ".join(f"a{r}_{p}" for p, _ in rows[r]) or "0"
        L.append(f"        d{r} = ({acc} + (1 << (_F{r} - 1))) >> _F{r}")
    L += _update_lines(True, nk, spec.reference is not None)
    return "\n".join(L) + "\n"
