"""The ``step`` methods of the generated Python module: float and bit-exact integer data paths.

Each function returns source lines of one piece of the algorithm listed in
:mod:`pressor.codegen.emit_python` (input check and prefilter, rho clamp/rate limit/cell search, corner
weights, delay line, row increments, anti-windup and output); :func:`float_step` and
:func:`fixed_step` assemble them into the two methods.
"""

from __future__ import annotations

from pressor.codegen.emit_spec import EmitSpec

__all__ = ["fixed_step", "float_step"]


def _reference_lines(spec: EmitSpec) -> list[str]:
    """The prefilter (pressor.synthesis.problem.reference), in double in both modes; sets e = r_m - MAP,
    uff. It runs on the feedback's own rho (clamped to the box and rate limited: r), K floored at
    the prefilter's K floor, T the fixed lag when the design sets one."""
    L = []
    L.append("        if not self._anchored:")
    L.append("            self._m0 = map_mmhg")
    L.append("            self._anchored = True")
    L.append("        m0 = self._m0")
    L.append("        rr = target_mmhg - m0")
    L.append("        kp = r[0]")
    L.append("        if kp < _PF_KLO:")
    L.append("            kp = _PF_KLO")
    L.append("        tp = _PF_TLAG" if spec.reference_lag_s is not None else "        tp = r[1]")
    L.append("        dp = r[2]")
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
    # what the model cannot reach at the pump's maximum joins the reference through its lag, so
    # the feedback brings MAP to the target whenever the pump can (the model's K may be too low)
    L.append("        sh = rr - kp * MAX_RATE_ML_H")
    L.append("        if sh < 0.0:")
    L.append("            sh = 0.0")
    L.append("        sf = self._sf")
    L.append("        self._sf = sf + cs * (sh - sf)")
    L.append("        rm = m0 + ym + sf")
    L.append("        self._rm = rm")
    L.append("        self._uff = uff")
    L.append("        e = rm - map_mmhg")
    return L


def _rho_block(fixed: bool, spec: EmitSpec) -> list[str]:
    """Clamp and rate-limit physical rho, locate the cell; leaves i0..i2 and fa, fb, fc, and x2 = tau
    (fractions in [0, 1] as floats, or quantised to the weight format in integer mode)."""
    L = []
    L.append("        clamped = False")
    L.append("        limited = False")
    L.append("        r = self._r")
    L.append("        started = self._started")
    if spec.bumpless:
        L.append("        kold = r[0]")
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
        if i == 0 and spec.k_rate_relative:  # log-K rates: a multiplicative limiter
            up, dn = "p * _KUP", "p * _KDN"
        else:
            up, dn = f"p + _RSTEP{i}", f"p - _RSTEP{i}"
        L.append(f"            if x > {up}:")
        L.append(f"                x = {up}")
        L.append("                limited = True")
        L.append(f"            elif x < {dn}:")
        L.append(f"                x = {dn}")
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


def _common_head(fixed: bool) -> list[str]:
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
    return L


def _error_lines(spec: EmitSpec, fixed: bool) -> list[str]:
    """After the rho block: the prefilter (sets e = r_m - MAP), the error's clamp and v_e."""
    L = _reference_lines(spec) if spec.reference is not None else []
    L.append("        if e > _E_LIM:")
    L.append("            e = _E_LIM")
    L.append("        elif e < -_E_LIM:")
    L.append("            e = -_E_LIM")
    if fixed:
        L.append("        v_e = int(e * _E_TO_Q)")
        L.append("        if v_e > _QMAX:")
        L.append("            v_e = _QMAX")
        L.append("        elif v_e < -_QMAX:")
        L.append("            v_e = -_QMAX")
    else:
        L.append("        v_e = e * _E_TO_S")
    return L


def _bumpless_lines(fixed: bool) -> list[str]:
    """The Smith law's bumpless integral (pressor.synthesis.families.smith.law): when the scheduled K moved
    from kold to r[0], x_e <- q x_e + (1 - q)(tau (yh + yd) / 2 - T e_p), q = r[0] / kold, with
    yh = x_k1 (the model output), yd its delayed value, e_p = e - yh + yd; in double, the same
    operations in both modes (the integer mode converts its Q0.31 values in and out)."""
    s1, s3, qe, back = (
        ("_BL_Q1", "_BL_Q3", "_BL_QE", "_BL_INV_Q3")
        if fixed
        else ("_BL_S1", "_BL_S3", "_E_LIM", "_BL_INV_S3")
    )
    L = []
    L.append("        if started and r[0] != kold:")
    L.append("            q = r[0] / kold")
    L.append(f"            yh = v1 * {s1}")
    L.append(f"            yd = v5 * {s1}")
    L.append(f"            ee = v6 * {qe}")
    L.append(f"            xe = v3 * {s3}")
    L.append(
        "            xe = q * xe + (1.0 - q) * (r[2] * (yh + yd) * 0.5 - r[1] * (ee - yh + yd))"
    )
    L.append(f"            x = xe * {back}")
    if fixed:
        L.append("            if x > 2147483647.0:")
        L.append("                x = 2147483647.0")
        L.append("            elif x < -2147483647.0:")
        L.append("                x = -2147483647.0")
        L.append("            x = int(x)")
    else:
        L.append("            if x > 1.0:")
        L.append("                x = 1.0")
        L.append("            elif x < -1.0:")
        L.append("                x = -1.0")
    L.append("            z[3] = x")
    L.append("            v3 = x")
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


def float_step(
    spec: EmitSpec, entries: list[tuple[int, int]], offs: list[int], nk: int, nz: int
) -> str:
    L = _common_head(False)
    L += _rho_block(False, spec)
    L += _error_lines(spec, False)
    L += _corner_lines(False)
    L += _delay_lines(False, nk)
    if spec.bumpless:
        L += _bumpless_lines(False)
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


def fixed_step(
    spec: EmitSpec, entries: list[tuple[int, int]], offs: list[int], nk: int, nz: int
) -> str:
    L = _common_head(True)
    L += _rho_block(True, spec)
    L += _error_lines(spec, True)
    L += _corner_lines(True)
    L += _delay_lines(True, nk)
    if spec.bumpless:
        L += _bumpless_lines(True)
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
