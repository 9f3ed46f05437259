"""The C target's ``lpvmap_step``: fixed-point (integer twin of the Python module) and float.

Each helper returns C source for one piece of the algorithm of :mod:`pressor.codegen.emit_python` (input
check and prefilter, rho clamp/rate limit/cell search, delay line, output); :func:`step_fixed` and
:func:`step_float` assemble the two bodies.
"""

from __future__ import annotations

from pressor.codegen.c_syntax import PU, P
from pressor.codegen.emit_spec import EmitSpec
from pressor.codegen.fixed_point import FixedPointPlan

__all__ = ["step_fixed", "step_float"]


def _rho_c(fixed: bool, spec: EmitSpec) -> str:
    """Clamp and rate-limit physical rho (double), bounded binary search, fractions fr[0..2]."""
    L = []
    if spec.bumpless:
        L.append("    started = s->started;")
        L.append("    kold = s->r[0];")
    for i, name in enumerate(("K", "T", "tau")):
        L.append(f"    x = {name};")
        L.append(f"    if (x < {PU}LO{i}) {{ x = {PU}LO{i}; clamped = 1; }}")
        L.append(f"    else if (x > {PU}HI{i}) {{ x = {PU}HI{i}; clamped = 1; }}")
        L.append("    if (s->started) {")
        if i == 0 and spec.k_rate_relative:  # log-K rates: a multiplicative limiter
            up, dn = f"s->r[0] * {PU}KUP", f"s->r[0] * {PU}KDN"
        else:
            up, dn = f"s->r[{i}] + {PU}RSTEP{i}", f"s->r[{i}] - {PU}RSTEP{i}"
        L.append(f"        if (x > {up}) {{ x = {up}; limited = 1; }}")
        L.append(f"        else if (x < {dn}) {{ x = {dn}; limited = 1; }}")
        L.append("    }")
        L.append(f"    s->r[{i}] = x;")
        L.append(f"    lo = 0; hi = {PU}N{i} - 1;")
        L.append("    while (hi - lo > 1) {")
        L.append("        mid = (lo + hi) >> 1;")
        L.append(f"        if (x >= {P}nodes{i}[mid]) lo = mid; else hi = mid;")
        L.append("    }")
        L.append(f"    idx[{i}] = lo;")
        L.append(f"    f = (x - {P}nodes{i}[lo]) * {P}invw{i}[lo];")
        L.append("    if (f > 1.0) f = 1.0;")
        L.append("    else if (f < 0.0) f = 0.0;")
        if fixed:
            L.append(f"    fr[{i}] = (int32_t)(f * {PU}WONE);")
        else:
            L.append(f"    fr[{i}] = f;")
    L.append("    s->started = 1;")
    return "\n".join(L)


def _reference_c(spec: EmitSpec) -> str:
    """The prefilter on the feedback's rho, the same double operations in the same order as the
    Python module."""
    tp = f"{PU}PF_TLAG" if spec.reference_lag_s is not None else "s->r[1]"
    return f"""
    if (!s->anchored) {{ s->m0 = map_mmhg; s->anchored = 1; }}
    rr = target_mmhg - s->m0;
    kp = s->r[0];
    if (kp < {PU}PF_KLO) kp = {PU}PF_KLO;
    tp = {tp};
    dp = s->r[2];
    ik = 1.0 / kp;
    dp = dp * {PU}INV_TS;
    n = (int32_t)dp;
    fdp = dp - n;
    i = s->phead - n;
    if (i < 0) i += {PU}NBUF;
    j = i - 1;
    if (j < 0) j += {PU}NBUF;
    s->qbuf[s->phead] = s->y0;
    pr = s->y0 + (s->ym - (s->qbuf[i] + (s->qbuf[j] - s->qbuf[i]) * fdp)); /* Smith correction */
    uff = (pr + tp * (rr - pr) * {PU}PF_INV_LAMBDA) * ik;
    cap = {PU}PF_UMAX;
    need = rr * ik;
    if (need > cap) cap = need > {PU}MAX_RATE_ML_H ? {PU}MAX_RATE_ML_H : need;
    if (uff > cap) uff = cap;
    else if (uff < 0.0) uff = 0.0;
    hs = {PU}PF_TS / tp;
    cs = hs * (1.0 - hs * (0.5 - hs * {PU}PF_SIXTH)); /* 1 - exp(-Ts/T) */
    s->y0 = s->y0 + cs * (kp * uff - s->y0);
    s->pbuf[s->phead] = uff;
    ud = s->pbuf[i] + (s->pbuf[j] - s->pbuf[i]) * fdp;
    s->phead += 1;
    if (s->phead == {PU}NBUF) s->phead = 0;
    ym = s->ym;
    s->ym = s->ym + cs * (kp * ud - s->ym);
    sh = rr - kp * {PU}MAX_RATE_ML_H; /* what the model cannot reach at the pump's maximum */
    if (sh < 0.0) sh = 0.0;
    sf = s->sf;
    s->sf = sf + cs * (sh - sf);
    rm = s->m0 + ym + sf;
    s->rm = rm;
    s->uff = uff;
    e = rm - map_mmhg;"""


def _bumpless_c(fixed: bool) -> str:
    """The Smith law's bumpless integral, the same double operations as the Python module."""
    s1, s3, qe, back = (
        (f"{PU}BL_Q1", f"{PU}BL_Q3", f"{PU}BL_QE", f"{PU}BL_INV_Q3")
        if fixed
        else (f"{PU}BL_S1", f"{PU}BL_S3", f"{PU}E_LIM", f"{PU}BL_INV_S3")
    )
    if fixed:
        clamp = """        if (bx > 2147483647.0) bx = 2147483647.0;
        else if (bx < -2147483647.0) bx = -2147483647.0;
        s->z[3] = (int32_t)bx;"""
    else:
        clamp = """        if (bx > 1.0) bx = 1.0;
        else if (bx < -1.0) bx = -1.0;
        s->z[3] = bx;"""
    return f"""    if (started && s->r[0] != kold) {{ /* bumpless integral: K moved from kold */
        double q, yh, yd, ee, xe, bx;
        q = s->r[0] / kold;
        yh = (double)v[1] * {s1};
        yd = (double)v[5] * {s1};
        ee = (double)v[6] * {qe};
        xe = (double)v[3] * {s3};
        xe = q * xe + (1.0 - q) * (s->r[2] * (yh + yd) * 0.5 - s->r[1] * (ee - yh + yd));
        bx = xe * {back};
{clamp}
        v[3] = s->z[3];
    }}
"""


def _input_c() -> str:
    return """    e = target_mmhg - map_mmhg;
    if (e - e != 0.0 || K - K != 0.0 || T - T != 0.0 || tau - tau != 0.0) {
        s->input_invalid = 1;
        return s->out;
    }
    s->input_invalid = 0;"""


def _error_c(spec: EmitSpec) -> str:
    """After the rho block: the prefilter (sets e = r_m - MAP) and the error's clamp."""
    ref = _reference_c(spec) if spec.reference is not None else ""
    return f"""{ref}
    if (e > {PU}E_LIM) e = {PU}E_LIM;
    else if (e < -{PU}E_LIM) e = -{PU}E_LIM;"""


def _delay_c(fixed: bool, nk: int, nz: int, W: int) -> str:
    """Ring-buffer write and fractional-delay read of x_k(t - tau) into v[nz..]; v = [z; x_d; e]."""
    if fixed:
        scalar, interp = "int32_t", f"(int32_t)((((int64_t)s->buf[k][j] - a) * fd) >> {W})"
    else:
        scalar, interp = "double", "(s->buf[k][j] - a) * fd"
    return f"""    h = s->head;
    i = h - n;
    if (i < 0) i += {PU}NBUF;
    j = i - 1;
    if (j < 0) j += {PU}NBUF;
    for (k = 0; k < {PU}N_K; ++k) {{
        {scalar} a;
        s->buf[k][h] = s->z[k];
        a = s->buf[k][i];
        v[{nz} + k] = a + {interp};
    }}
    h += 1;
    if (h == {PU}NBUF) h = 0;
    s->head = h;
    for (k = 0; k < {PU}N_Z; ++k) v[k] = s->z[k];
    v[{nz + nk}] = ve;"""


def _output_c(fixed: bool, reference: bool) -> str:
    total = "(un + uffs)" if reference else "un"
    if fixed:
        conv = f"out = (double){total} * {PU}U_Q_TO_ML_H;"
    else:
        conv = f"out = {total} * {PU}U_SCALE;"
    return f"""    if (out > {PU}MAX_RATE_ML_H) out = {PU}MAX_RATE_ML_H;
    else if (out < 0.0) out = 0.0;
    s->out = out;
    s->rho_clamped = clamped;
    s->rho_rate_limited = limited;
    return out;
}}
""".replace("    if (out >", f"    {conv}\n    if (out >", 1)


def _reference_decl(reference: bool, share: str) -> str:
    if not reference:
        return ""
    return (
        "    double rr, kp, tp, dp, ik, pr, uff, cap, need, hs, cs, fdp, ud, rm, ym, sh, sf;\n"
        f"    {share} uffs, uhi;\n"
    )


def _ff_share_c(reference: bool, fixed: bool) -> str:
    """The feedforward's share of the command state's range (the feedback is clamped to the rest)."""
    if not reference:
        return ""
    if fixed:
        return f"    uffs = (int64_t)(uff * {PU}U_TO_Q);\n    uhi = {PU}U_MAX_Q - uffs;\n"
    return f"    uffs = uff * {PU}INV_U_SCALE;\n    uhi = {PU}U_MAX_S - uffs;\n"


def _kold_decl(spec: EmitSpec) -> str:
    return "    int32_t started;\n    double kold;" if spec.bumpless else ""


def step_fixed(spec: EmitSpec, plan: FixedPointPlan, nk: int, nz: int, W: int) -> str:
    nt, na = spec.counts[1], spec.counts[2]
    ref = spec.reference is not None
    uhi, ulo = ("uhi", "-uffs") if ref else (f"{PU}U_MAX_Q", "0")
    ctype = "int16_t" if plan.coef_bits <= 15 else "int32_t"
    return f"""double {P}step({P}state_t *s, double map_mmhg, double target_mmhg, double K, double T,
                  double tau)
{{
    double e, x, f, out, dd;
    int32_t idx[3], fr[3], one, t00, t01, t10, t11, w[8], ve, n, fd, h, i, j, k, lo, hi, mid;
    int32_t v[{2 * nk + 3}], m[{PU}NENT], b;
    int64_t acc, dz[{nz - 1}], un, dxe, xs;
    const {ctype} *cp[8];
    uint8_t clamped = 0, limited = 0, freeze = 0;
{_kold_decl(spec)}
{_reference_decl(ref, "int64_t")}{_input_c()}
{_rho_c(True, spec)}{_error_c(spec)}
    x = e * {PU}E_TO_Q;
    if (x > 2147483647.0) x = 2147483647.0;
    else if (x < -2147483647.0) x = -2147483647.0;
    ve = (int32_t)x;
    one = INT32_C(1) << {W};
    t00 = (int32_t)(((int64_t)(one - fr[0]) * (one - fr[1])) >> {W});
    t01 = (int32_t)(((int64_t)(one - fr[0]) * fr[1]) >> {W});
    t10 = (int32_t)(((int64_t)fr[0] * (one - fr[1])) >> {W});
    t11 = (int32_t)(((int64_t)fr[0] * fr[1]) >> {W});
    w[0] = (int32_t)(((int64_t)t00 * (one - fr[2])) >> {W});
    w[1] = (int32_t)(((int64_t)t00 * fr[2]) >> {W});
    w[2] = (int32_t)(((int64_t)t01 * (one - fr[2])) >> {W});
    w[3] = (int32_t)(((int64_t)t01 * fr[2]) >> {W});
    w[4] = (int32_t)(((int64_t)t10 * (one - fr[2])) >> {W});
    w[5] = (int32_t)(((int64_t)t10 * fr[2]) >> {W});
    w[6] = (int32_t)(((int64_t)t11 * (one - fr[2])) >> {W});
    w[7] = (int32_t)(((int64_t)t11 * fr[2]) >> {W});
    /* delay D = tau / Ts samples (scheduled tau), fraction in the weight format */
    dd = s->r[2] * {PU}INV_TS;
    if (dd > {PU}DMAX_SAMPLES) dd = {PU}DMAX_SAMPLES;
    n = (int32_t)dd;
    fd = (int32_t)((dd - n) * {PU}WONE);
{_delay_c(True, nk, nz, W)}
{_bumpless_c(True) if spec.bumpless else ""}    b = (idx[0] * {nt} + idx[1]) * {na} + idx[2];
    for (k = 0; k < 8; ++k) cp[k] = {P}tab[b + {P}corner[k]];
    for (k = 0; k < {PU}NENT; ++k) {{
        acc = 0;
        for (i = 0; i < 8; ++i) acc += (int64_t)w[i] * cp[i][k];
        m[k] = (int32_t)(acc >> {W});
    }}
    for (k = 0; k < {nz - 1}; ++k) dz[k] = 0;
    for (k = 0; k < {PU}NENT; ++k) dz[{P}row[k]] += (int64_t)m[k] * v[{P}col[k]];
    for (k = 0; k < {nz - 1}; ++k) dz[k] = (dz[k] + (INT64_C(1) << ({P}rshift[k] - 1))) >> {P}rshift[k];
{_ff_share_c(ref, True)}    un = (int64_t)s->z[{nk}] + dz[{nk}];
    if (un > {uhi}) {{ un = {uhi}; freeze = ve > 0; s->saturated = 1; }}
    else if (un < {ulo}) {{ un = {ulo}; freeze = ve < 0; s->saturated = 1; }}
    else s->saturated = 0;
    s->z[{nk}] = (int32_t)un;
    if (!freeze) {{
        dxe = ((int64_t)ve * {PU}XE_Q + (INT64_C(1) << ({PU}XE_SHIFT - 1))) >> {PU}XE_SHIFT;
        for (k = 0; k < {nz}; ++k) {{
            if (k == {nk}) continue;
            xs = (int64_t)s->z[k] + (k == {nk + 1} ? dxe : dz[k]);
            if (xs > {PU}QMAX) xs = {PU}QMAX;
            else if (xs < -{PU}QMAX) xs = -{PU}QMAX;
            s->z[k] = (int32_t)xs;
        }}
    }}
{_output_c(True, ref)}"""


def step_float(spec: EmitSpec, nk: int, nz: int) -> str:
    nt, na = spec.counts[1], spec.counts[2]
    ref = spec.reference is not None
    uhi, ulo = ("uhi", "-uffs") if ref else (f"{PU}U_MAX_S", "0.0")
    return f"""double {P}step({P}state_t *s, double map_mmhg, double target_mmhg, double K, double T,
                  double tau)
{{
    double e, x, f, out, fr[3], w[8], t00, t01, t10, t11, ve, d, fd, v[{2 * nk + 3}];
    double dz[{nz - 1}], part[{nz - 1}], un, xs;
    int32_t idx[3], n, h, i, j, k, c, b, lo, hi, mid;
    const double *cp;
    uint8_t clamped = 0, limited = 0, freeze = 0;
{_kold_decl(spec)}
{_reference_decl(ref, "double")}{_input_c()}
{_rho_c(False, spec)}{_error_c(spec)}
    ve = e * {PU}E_TO_S;
    t00 = (1.0 - fr[0]) * (1.0 - fr[1]);
    t01 = (1.0 - fr[0]) * fr[1];
    t10 = fr[0] * (1.0 - fr[1]);
    t11 = fr[0] * fr[1];
    w[0] = t00 * (1.0 - fr[2]); w[1] = t00 * fr[2];
    w[2] = t01 * (1.0 - fr[2]); w[3] = t01 * fr[2];
    w[4] = t10 * (1.0 - fr[2]); w[5] = t10 * fr[2];
    w[6] = t11 * (1.0 - fr[2]); w[7] = t11 * fr[2];
    d = s->r[2] * {PU}INV_TS;
    if (d > {PU}DMAX_SAMPLES) d = {PU}DMAX_SAMPLES;
    n = (int32_t)d;
    fd = d - n;
{_delay_c(False, nk, nz, 0)}
{_bumpless_c(False) if spec.bumpless else ""}    b = (idx[0] * {nt} + idx[1]) * {na} + idx[2];
    for (k = 0; k < {nz - 1}; ++k) dz[k] = 0.0;
    for (c = 0; c < 8; ++c) {{
        cp = {P}tab[b + {P}corner[c]];
        for (k = 0; k < {nz - 1}; ++k) part[k] = 0.0;
        for (k = 0; k < {PU}NENT; ++k) part[{P}row[k]] += cp[k] * v[{P}col[k]];
        for (k = 0; k < {nz - 1}; ++k) dz[k] += w[c] * part[k];
    }}
{_ff_share_c(ref, False)}    un = s->z[{nk}] + dz[{nk}];
    if (un > {uhi}) {{ un = {uhi}; freeze = ve > 0.0; s->saturated = 1; }}
    else if (un < {ulo}) {{ un = {ulo}; freeze = ve < 0.0; s->saturated = 1; }}
    else s->saturated = 0;
    s->z[{nk}] = un;
    if (!freeze) {{
        for (k = 0; k < {nz}; ++k) {{
            if (k == {nk}) continue;
            xs = s->z[k] + (k == {nk + 1} ? ve * {PU}XE_GAIN : dz[k]);
            if (xs > 1.0) xs = 1.0;
            else if (xs < -1.0) xs = -1.0;
            s->z[k] = xs;
        }}
    }}
{_output_c(False, ref)}"""
