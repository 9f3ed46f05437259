"""The Wirtinger-based analysis LMI split into its rate-free part and one term per moving parameter.

The LMI of :mod:`pressor.synthesis.certificates.wirtinger.analysis` at a grid point rho_k and a rate vertex
sigma is affine in sigma::

    LMI(rho_k, sigma) = L0(rho_k) + sum_i sigma_i M_i(rho_k),     sigma in {-1, +1}^s

    L0  = He(G1' P G0) + Ex'S Ex - Eh'S Eh + taubar^2 Ga'R Ga - (taubar/tau)(E1'R E1 + 3 E2'R E2)
          - mu Ew'Ew + Gz'Gz                       (G0 at dtau/dt = 0)
    M_i = G1' D_i G1 + c_i (He(G1' P Eg) + Eh'S Eh),   D_i = nu_i dP/drho_i,  c_i = nu_i dtau/drho_i

(``Eg zeta = [0; x(t - tau)]``: the d/dt int x row of G0 is ``x - (1 - dtau) x(t - tau)``; nu_i is
the rate bound of rho_hat_i in scaled time). Everything is linear in the *local* variables of the
point, ``[P(rho_k), D_1..D_s', S, R, mu]`` (only the s' moving parameters: nonzero rate, and P or
the delay depends on them), and the local variables are a fixed sparse linear map ``T_k`` of the
global ones ``x = [P basis terms, S, R, mu]``. :func:`point_maps` gives the exact maps of L0 and
every M_i on the local variables (by unit probes, in Clarabel's PSD-triangle order);
:func:`vertex_lmis` evaluates every vertex LMI at a solution for the re-check.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from pressor.synthesis.certificates.state_transform import transform_of
from pressor.synthesis.certificates.wirtinger.k_scaling import KScaling, k_scaled_system, k_terms
from pressor.synthesis.problem.basis import basis_terms
from pressor.synthesis.problem.closed_loop import DelaySystem
from pressor.synthesis.solver.conic import svec_rows

__all__ = [
    "WirtingerData",
    "chop_roundoff",
    "point_maps",
    "prepare",
    "sym",
    "vertex_lmis",
    "young_maps",
]

Array = NDArray[np.float64]

#: points evaluated per batch (bounds the probe arrays to ~ nloc x batch x (1 + s') x big^2)
_BATCH = 12
#: a probed coefficient below this many unit round-offs of its point's largest coefficient is
#: cancellation residue (1e-22..1e-16 where the exact value is 0), not data: the true nonzero
#: coefficients of the shipped design are >= 2e-6 of the largest (10 orders above the residue)
ROUNDOFF_ULPS = 64.0


def chop_roundoff(maps: Array) -> Array:
    """``maps`` (P, ...) with every entry below :data:`ROUNDOFF_ULPS` unit round-offs of its own
    point's largest entry (the first axis indexes points) set to exactly 0.

    Why: the unit probes evaluate sums of products of the scaled data, and a coefficient whose
    exact value is 0 comes out as residue whose bits depend on the BLAS/SIMD kernels that summed
    it. Handed to the solver it is a real constraint coefficient: rows of such residue alone
    (1e-18 norm) sit in every Young block, and the interior-point method's KKT factorisation then
    differs by CPU family (on an AVX2-only CPU Clarabel's default backend stopped at iteration 1
    with a NumericalError). Zeroing it makes the conic data the same bits on every machine and
    removes those rows; the re-check (the verdict) evaluates the unchopped LMIs.
    """
    flat = np.abs(maps.reshape(maps.shape[0], -1))
    tol = ROUNDOFF_ULPS * np.finfo(float).eps * flat.max(axis=1, initial=0.0)
    return np.where(np.abs(maps) < tol.reshape(-1, *(1,) * (maps.ndim - 1)), 0.0, maps)


def sym(vec: Array, n: int) -> Array:
    """Symmetric (…, n, n) matrices from their upper-triangle entries (…, n(n+1)/2)."""
    iu = np.triu_indices(n)
    out = np.zeros((*vec.shape[:-1], n, n))
    out[..., iu[0], iu[1]] = vec
    out[..., iu[1], iu[0]] = vec
    return out


@dataclass(frozen=True)
class WirtingerData:
    """The scaled data of one problem and the layout of its global and local variables."""

    g1: Array  # (m, 2n, big): G1 zeta = [x; h v]
    g0: Array  # (m, 2n, big): G0 zeta = d/dt [x; int x] at dtau/dt = 0
    ga: Array  # (m, n, big): [A Ad 0 B]
    const: Array  # (m, big, big): Gz'Gz
    h: Array  # (m,) tau / time scale
    hbar: float
    w_p: Array  # (m, n_p) P basis weights
    dw_m: Array  # (m, n_p, s') nu_i d w / d rho_i of the moving parameters
    c_tau: Array  # (s',) nu_i d tau / d rho_i (s/s)
    moving: tuple[int, ...]  # moving parameter indices (K-scaled: then s, the r coordinate)
    n: int
    nw: int
    tx: Array
    txi: Array
    time_scale_s: float
    #: K-scaled coordinates only: (m, s', n, big) direction of Ga = [A Ad 0 B] at rate vertex
    #: sigma_i = +1 (kappa on the K vertex, r on the last one), see
    #: :mod:`pressor.synthesis.certificates.wirtinger.k_scaling`
    dga: Array | None = None
    #: the same directions factored, ``Delta = U Phi``: (U (m, 2, n, n_s), Phi (2, n_s, big),
    #: position of the K vertex in ``moving``) for kappa and r (:func:`young_maps`)
    young: tuple[Array, Array, int] | None = None

    @property
    def big(self) -> int:
        return 3 * self.n + self.nw

    @property
    def ns2(self) -> int:
        return self.n * (2 * self.n + 1)

    @property
    def ns(self) -> int:
        return self.n * (self.n + 1) // 2

    @property
    def n_p(self) -> int:
        return self.w_p.shape[1]

    @property
    def nvar(self) -> int:
        """Global variables: P basis terms, S, R, mu."""
        return self.n_p * self.ns2 + 2 * self.ns + 1

    @property
    def n_pd(self) -> int:
        """Local P(rho_k) and D_i entries (the part of the local variables T_k maps from P terms)."""
        return self.ns2 * (1 + len(self.moving))

    @property
    def nloc(self) -> int:
        return self.n_pd + 2 * self.ns + 1


def prepare(
    systems: Sequence[DelaySystem],
    rho_hat: Array,
    rate: Array,
    dtau: Array,
    tau_max: float,
    taus: Array,
    p_dependence: str,
    p_params: Sequence[int],
    time_scale_s: float,
    state_transform: Array | None,
    k_scaling: KScaling | None = None,
) -> WirtingerData:
    """Scale time and state (:func:`pressor.synthesis.certificates.state_transform.transform_of`), build G1,
    G0, Ga, Gz'Gz and the P basis; a parameter moves if its rate is > 0 and P or tau depends on it.

    With ``k_scaling`` the systems are first written in ``x~ = D(K) x``
    (:func:`pressor.synthesis.certificates.wirtinger.k_scaling.k_scaled_system`; ``state_transform`` then
    acts on x~), Ad is taken at the centre of each point's r interval, K moves whenever its rate
    bound is > 0, and r is one more moving coordinate (index ``s``, after the parameters) with no P
    or tau term.
    """
    ts = float(time_scale_s)
    if k_scaling is not None:
        k_scaling.check(len(systems), systems[0].n, rho_hat.shape[1], tau_max)
        systems = [
            k_scaled_system(q, float(kk), k_scaling.states)
            for q, kk in zip(systems, k_scaling.k, strict=True)
        ]
    n, nw = systems[0].n, systems[0].B.shape[1]
    m = len(systems)
    tx, txi = transform_of(systems, ts, state_transform)
    a = np.stack([ts * txi @ q.A @ tx for q in systems])
    ad = np.stack([ts * txi @ q.Ad @ tx for q in systems])
    b = np.stack([ts * txi @ q.B for q in systems])
    c = np.stack([q.C @ tx for q in systems])
    cd = np.stack([q.Cd @ tx for q in systems])
    d = np.stack([q.D for q in systems])
    h = taus / ts
    k_moves = k_scaling is not None and k_scaling.k_rate_per_s > 0
    if k_moves:
        ad, (u_kappa, phi_kappa), (u_r, phi_r), ga_c = k_terms(
            k_scaling, ad, tx, txi, ts, tau_max, nw
        )
    ga = np.concatenate([a, ad, np.zeros((m, n, n)), b], axis=2)
    if k_moves and np.any(ga_c != 0.0):
        ga = ga + ga_c
    gz = np.concatenate([c, cd, np.zeros((m, c.shape[1], n)), d], axis=2)
    g1 = np.zeros((m, 2 * n, 3 * n + nw))
    g1[:, :n, :n] = np.eye(n)
    g1[:, n:, 2 * n : 3 * n] = h[:, None, None] * np.eye(n)
    g0 = np.zeros_like(g1)
    g0[:, :n, :] = ga
    g0[:, n:, :n] = np.eye(n)
    g0[:, n:, n : 2 * n] = -np.eye(n)
    w_p, dw_p = basis_terms(rho_hat, p_dependence, p_params)
    moving = tuple(
        i
        for i in range(rho_hat.shape[1])
        if rate[i] > 0 and (np.any(dw_p[:, :, i] != 0) or dtau[i] != 0)
    )
    mv = list(moving)
    dw_m = dw_p[:, :, mv] * (rate[mv] * ts)[None, None, :]
    c_tau = rate[mv] * dtau[mv]
    dga, young = None, None
    if k_moves:
        s = rho_hat.shape[1]
        ik = k_scaling.k_index
        moving = tuple(sorted({*moving, ik})) + (s,)
        real = list(moving[:-1])
        dw_m = np.concatenate(
            [dw_p[:, :, real] * (rate[real] * ts)[None, None, :], np.zeros((m, w_p.shape[1], 1))],
            axis=2,
        )
        c_tau = np.append(rate[real] * dtau[real], 0.0)
        # kappa and r factors padded to a common number of selector rows (zero rows add nothing)
        q = max(phi_kappa.shape[0], phi_r.shape[0])
        phi = np.zeros((2, q, 3 * n + nw))
        u_both = np.zeros((m, 2, n, q))
        phi[0, : phi_kappa.shape[0]], u_both[:, 0, :, : phi_kappa.shape[0]] = phi_kappa, u_kappa
        phi[1, : phi_r.shape[0]], u_both[:, 1, :, : phi_r.shape[0]] = phi_r, u_r
        young = (u_both, phi, moving.index(ik))
        dga = np.zeros((m, len(moving), n, 3 * n + nw))
        dga[:, [young[2], -1]] = np.einsum("mjns,jsb->mjnb", young[0], phi)
    return WirtingerData(
        g1=g1,
        g0=g0,
        ga=ga,
        const=np.einsum("mra,mrb->mab", gz, gz),
        h=h,
        hbar=tau_max / ts,
        w_p=w_p,
        dw_m=dw_m,
        c_tau=c_tau,
        moving=moving,
        n=n,
        nw=nw,
        tx=tx,
        txi=txi,
        time_scale_s=ts,
        dga=dga,
        young=young,
    )


def local_map(data: WirtingerData, k: int) -> sp.csr_matrix:
    """``T_k``: the P(rho_k) and D_i rows of the local variables as a map of the P basis terms
    (n_pd x n_p ns2); S, R, mu are the global ones."""
    rows = [data.w_p[k]] + [data.dw_m[k, :, i] for i in range(len(data.moving))]
    return sp.kron(sp.csr_matrix(np.array(rows)), sp.eye(data.ns2), format="csr")


def _parts(
    data: WirtingerData,
    loc: Array,
    pts: NDArray[np.int64],
    quad_bound: bool = True,
    dga_linear: bool = True,
) -> tuple[Array, Array]:
    """L0 without Gz'Gz, (J, P, big, big), and M (J, P, s', big, big) for local vectors
    ``loc`` (J, P, nloc) at the points ``pts`` (P of them).

    K-scaled coordinates (``data.dga``): Ga = Ga0 + sum_i sigma_i Delta_i, so M_i gains
    ``He(G1' P [Delta_i; 0]) + taubar^2 He(Ga0' R Delta_i)`` and the rest,
    ``taubar^2 Delta' R Delta``, is bounded by ``taubar^2 q sum_i Delta_i' R Delta_i`` (q the
    number of nonzero directions) in L0 when ``quad_bound``; otherwise it is left out (the
    re-check adds it exactly per vertex). ``dga_linear=False`` leaves out the M_i terms of
    Delta (the bound form takes them by :func:`young_maps` instead)."""
    n, n2, ns, ns2, n_pd = data.n, 2 * data.n, data.ns, data.ns2, data.n_pd
    nm, big = len(data.moving), data.big
    j, npt = loc.shape[:2]
    p = sym(loc[..., :ns2], n2)
    dmat = sym(loc[..., ns2:n_pd].reshape(j, npt, nm, ns2), n2)
    sm = sym(loc[..., n_pd : n_pd + ns], n)
    rm = sym(loc[..., n_pd + ns : n_pd + 2 * ns], n)
    mu = loc[..., -1]
    g1, g0, ga, h = data.g1[pts], data.g0[pts], data.ga[pts], data.h[pts]

    def embed(mat: Array, r0: int) -> Array:  # an n x n block at rows/cols r0 of a big matrix
        out = np.zeros((*mat.shape[:-2], big, big))
        out[..., r0 : r0 + n, r0 : r0 + n] = mat
        return out

    def wirt(r: Array) -> Array:  # E1'R E1 + 3 E2'R E2, E1 = [I -I 0 0], E2 = [I I -2I 0]
        out = np.zeros((*r.shape[:-2], big, big))
        for coef, weight in (((1.0, -1.0, 0.0), 1.0), ((1.0, 1.0, -2.0), 3.0)):
            for bi in range(3):
                for bj in range(3):
                    out[..., bi * n : bi * n + n, bj * n : bj * n + n] += (
                        weight * coef[bi] * coef[bj] * r
                    )
        return out

    he = np.einsum("pra,jprs,psb->jpab", g1, p, g0, optimize=True)
    l0 = he + np.swapaxes(he, -1, -2)
    l0 += embed(sm, 0) - embed(sm, n)
    l0 += data.hbar**2 * np.einsum("pra,jprs,psb->jpab", ga, rm, ga, optimize=True)
    l0 -= (data.hbar / h)[None, :, None, None] * wirt(rm)
    idx = np.arange(3 * n, big)
    l0[..., idx, idx] -= mu[..., None]
    eg = np.zeros((n2, big))
    eg[n:, n : 2 * n] = np.eye(n)
    hg = np.einsum("pra,jprs,sb->jpab", g1, p, eg, optimize=True)
    rate_tau = hg + np.swapaxes(hg, -1, -2) + embed(sm, n)
    mt = np.einsum("pra,jpirs,psb->jpiab", g1, dmat, g1, optimize=True)
    mt += data.c_tau[None, None, :, None, None] * rate_tau[:, :, None]
    if data.dga is not None:
        dq = data.dga[pts]
        if dga_linear:
            dm = np.einsum("pra,jprs,pisb->jpiab", g1, p[..., :n], dq, optimize=True)
            dm += data.hbar**2 * np.einsum("psa,jpst,pitb->jpiab", ga, rm, dq, optimize=True)
            mt += dm + np.swapaxes(dm, -1, -2)
        if quad_bound:
            nq = np.count_nonzero(np.any(data.dga != 0.0, axis=(0, 2, 3)))
            l0 += (nq * data.hbar**2) * np.einsum("pisa,jpst,pitb->jpab", dq, rm, dq, optimize=True)
    return l0, mt


def young_maps(data: WirtingerData, pts: NDArray[np.int64]) -> Array:
    """``W_j`` (P, 2, big * n_s, nloc) at ``pts`` as maps of the local variables: the kappa (j = 0)
    and r (j = 1) terms of M are ``He(W_j Phi_j)``, ``W_j = (G1' P[:, :n] + taubar^2 Ga0' R) U_j``
    (row-major (big, n_s) entries; ``data.young`` holds U_j and Phi_j)."""
    n, ns, n_pd, nloc = data.n, data.ns, data.n_pd, data.nloc
    u = data.young[0]
    out = []
    for lo in range(0, len(pts), _BATCH):
        sub = pts[lo : lo + _BATCH]
        unit = np.broadcast_to(np.eye(nloc)[:, None, :], (nloc, len(sub), nloc))
        p = sym(unit[..., : data.ns2], 2 * n)
        rm = sym(unit[..., n_pd + ns : n_pd + 2 * ns], n)
        w = np.einsum("pra,jprs,pisc->jpiac", data.g1[sub], p[..., :n], u[sub], optimize=True)
        w += data.hbar**2 * np.einsum(
            "psa,jpst,pitc->jpiac", data.ga[sub], rm, u[sub], optimize=True
        )
        out.append(np.moveaxis(w.reshape(nloc, len(sub), 2, -1), 0, -1))
    return chop_roundoff(np.concatenate(out))


def point_maps(
    data: WirtingerData, pts: NDArray[np.int64], dga_linear: bool = True
) -> tuple[Array, Array, Array]:
    """Exact maps at ``pts`` on the local variables, in Clarabel's PSD-triangle order:
    ``F0`` (P, nsv, nloc) and ``FM`` (P, s', nsv, nloc) with ``svec(L0) = F0 loc + f0`` and
    ``svec(M_i) = FM_i loc``, and ``f0`` (P, nsv) = svec(Gz'Gz); ``dga_linear`` as in
    :func:`_parts`."""
    idx, wsv = svec_rows(data.big)
    nloc = data.nloc
    f0_all, fm_all = [], []
    for lo in range(0, len(pts), _BATCH):
        sub = pts[lo : lo + _BATCH]
        unit = np.broadcast_to(np.eye(nloc)[:, None, :], (nloc, len(sub), nloc))
        l0, mt = _parts(data, unit, sub, dga_linear=dga_linear)
        f0_all.append(np.moveaxis(l0.reshape(nloc, len(sub), -1)[..., idx] * wsv, 0, -1))
        fm_all.append(
            np.moveaxis(mt.reshape(nloc, len(sub), mt.shape[2], data.big**2)[..., idx] * wsv, 0, -1)
        )
    const = data.const[pts].reshape(len(pts), -1)[:, idx] * wsv
    f0, fm = np.concatenate(f0_all), np.concatenate(fm_all)
    return chop_roundoff(f0), chop_roundoff(fm), chop_roundoff(const)


def local_values(data: WirtingerData, x: Array) -> Array:
    """The local variables (m, nloc) of every point for the global vector x (nvar,)."""
    ns2, n_p = data.ns2, data.n_p
    c = x[: n_p * ns2].reshape(n_p, ns2)
    p = data.w_p @ c
    dm = np.einsum("mjs,je->mse", data.dw_m, c).reshape(len(p), -1)
    rest = np.broadcast_to(x[n_p * ns2 :], (len(p), data.nvar - n_p * ns2))
    return np.concatenate([p, dm, rest], axis=1)


def vertex_lmis(data: WirtingerData, x: Array, vertices: Array) -> Array:
    """Every vertex LMI (m, nv, big, big) at the global vector x (the re-check's input); in
    K-scaled coordinates with the exact ``taubar^2 Delta_v' R Delta_v`` of each vertex."""
    loc = local_values(data, x)
    out = []
    for lo in range(0, len(loc), _BATCH):
        pts = np.arange(lo, min(len(loc), lo + _BATCH))
        l0, mt = _parts(data, loc[None, pts], pts, quad_bound=False)
        val = l0[0][:, None] + np.einsum("vi,piab->pvab", vertices, mt[0])
        if data.dga is not None:
            n, ns, n_pd = data.n, data.ns, data.n_pd
            rm = sym(loc[pts, n_pd + ns : n_pd + 2 * ns], n)
            dv = np.einsum("vi,pinb->pvnb", vertices, data.dga[pts])
            val += data.hbar**2 * np.einsum("pvsa,pst,pvtb->pvab", dv, rm, dv, optimize=True)
        out.append(val + data.const[pts][:, None])
    return np.concatenate(out)
