"""Conic data of the Wirtinger analysis LMI at a set of imposed points: two rate forms, two couplings.

Rate forms (L0, M_i of :mod:`pressor.synthesis.certificates.wirtinger.lmi`; s' moving parameters):

* ``"vertex"``: ``L0 + sum_i sigma_i M_i <= -eps I`` at every sigma in {-1, +1}^s' (2^s' PSD blocks
  of size 3n + n_w per point), the formulation measured in docs/notes/certificate-structure.md.
* ``"bound"``: one LMI per point, ``L0 + sum_i E_i' Z_i E_i <= -eps I`` with symmetric slacks
  ``Z_i >= M_i`` and ``Z_i >= -M_i`` restricted to the rows and columns ``E_i`` where M_i can be
  nonzero (2n for a parameter that only moves P; 3n for the delay, whose rate also multiplies P
  and S). For any rate vector with |sigma_i| <= 1, ``sigma_i M_i <= |sigma_i| Z_i <= Z_i`` (Z_i >= 0
  follows from Z_i >= +/- M_i), so ``LMI(sigma) <= L0 + sum_i Z_i <= -eps I``: the bound form
  implies every vertex LMI (and every rate inside the bounds); with one moving parameter and full
  Z it is equivalent to the vertex form (take Z = -L0 - eps I).

K-scaled coordinates (``data.young``, :mod:`pressor.synthesis.certificates.wirtinger.k_scaling`): the bound
form takes the kappa and r directions by Young's inequality, one block of size big + 2 n_s per point
(:func:`pressor.synthesis.certificates.wirtinger.analysis.analyse_wirtinger` gives the inequality and why it
suffices).

Couplings of the P basis terms (the ~n_p (2n)(2n+1)/2 variables every point shares):

* ``"dense"``: each LMI is written directly in the basis terms (``P(rho_k) = sum_j w_kj P_j``).
* ``"per_point"``: each imposed point gets its own copy ``y_k = [P(rho_k); D_1..D_s']`` tied to the
  basis terms by the equality ``y_k = T_k [P_j]`` (a few nonzeros per row); the PSD blocks then
  touch only y_k, S, R, mu and the point's slacks, which keeps the KKT system sparse.

Both are exact rewritings (same feasible set in the global variables).
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from pressor.synthesis.certificates.wirtinger.lmi import (
    WirtingerData,
    local_map,
    point_maps,
    young_maps,
)
from pressor.synthesis.solver.conic import svec_eye, svec_rows

__all__ = ["ConicData", "RATE_FORMS", "COUPLINGS", "build_conic", "vertices_of", "svec_of_triu"]

RATE_FORMS = ("vertex", "bound")
COUPLINGS = ("dense", "per_point")

Array = NDArray[np.float64]
ConicData = tuple[Array, sp.csc_matrix, Array, list[Any], int, int]


def vertices_of(data: WirtingerData) -> Array:
    """Rate vertices (nv, s') of the moving parameters (one empty vertex if none moves)."""
    combos = list(itertools.product((-1.0, 1.0), repeat=len(data.moving)))
    return np.array(combos, dtype=float).reshape(len(combos), len(data.moving))


def svec_of_triu(n: int) -> sp.csr_matrix:
    """Map from the upper-triangle entries of a symmetric n x n matrix (``np.triu_indices``
    order, as :func:`pressor.synthesis.certificates.wirtinger.lmi.sym` reads them) to its Clarabel PSD
    triangle."""
    tri = np.zeros((n, n), dtype=np.int64)
    tri[np.triu_indices(n)] = np.arange(n * (n + 1) // 2)
    idx, w = svec_rows(n)
    rr, cc = idx // n, idx % n
    return sp.csr_matrix((w, (np.arange(len(idx)), tri[np.minimum(rr, cc), np.maximum(rr, cc)])))


def _supports(fm: Array, big: int) -> list[NDArray[np.int64]]:
    """Rows/columns of the big matrix where each M_i has a nonzero coefficient (any point)."""
    idx, _ = svec_rows(big)
    out = []
    for i in range(fm.shape[1]):
        nz = np.flatnonzero(np.any(fm[:, i] != 0.0, axis=(0, 2)))
        out.append(np.union1d(idx[nz] // big, idx[nz] % big).astype(np.int64))
    return out


def _sub_rows(support: NDArray[np.int64], big: int) -> NDArray[np.int64]:
    """Positions in the big PSD triangle of the entries of the support's own PSD triangle."""
    idx, _ = svec_rows(big)
    where = np.full(big * big, -1, dtype=np.int64)
    where[idx] = np.arange(len(idx))
    sub_idx, _ = svec_rows(len(support))
    r, c = support[sub_idx // len(support)], support[sub_idx % len(support)]
    return where[np.minimum(r, c) * big + np.maximum(r, c)]


def _young_layout(big: int, phi: Array) -> tuple[sp.csr_matrix, list[sp.csr_matrix], Array]:
    """PSD-triangle layout of the Young block of size ``bb = big + 2 n_s``: the embedding of the
    big triangle (nsv_bb x nsv_big), the placement of each W_j's (big, n_s) entries at rows
    0..big, columns big + j n_s.. (nsv_bb x big n_s, weight sqrt 2), and the svec of
    ``[[Phi_j' Phi_j, 0], [0, -I_j]]`` (2, nsv_bb): the coefficient of e_j."""
    nsel = phi.shape[1]
    bb = big + 2 * nsel
    idx_bb, w_bb = svec_rows(bb)
    where = np.full(bb * bb, -1, dtype=np.int64)
    where[idx_bb] = np.arange(len(idx_bb))
    idx, _ = svec_rows(big)
    r, c = idx // big, idx % big
    rows = where[np.minimum(r, c) * bb + np.maximum(r, c)]
    emb = sp.csr_matrix(
        (np.ones(len(idx)), (rows, np.arange(len(idx)))), shape=(len(idx_bb), len(idx))
    )
    place, e_svec = [], []
    rr, cc = np.divmod(np.arange(big * nsel), nsel)
    for j in range(2):
        pos = where[rr * bb + big + j * nsel + cc]
        place.append(
            sp.csr_matrix(
                (np.full(len(pos), np.sqrt(2.0)), (pos, np.arange(len(pos)))),
                shape=(len(idx_bb), big * nsel),
            )
        )
        mat = np.zeros((bb, bb))
        mat[:big, :big] = phi[j].T @ phi[j]
        d = big + j * nsel + np.arange(nsel)
        mat[d, d] = -1.0
        e_svec.append(mat.reshape(-1)[idx_bb] * w_bb)
    return emb, place, np.array(e_svec)


def build_conic(
    data: WirtingerData,
    pts: NDArray[np.int64],
    rate_form: str,
    coupling: str,
    epsilon: float,
    gamma_cap: float | None,
) -> ConicData:
    """``(q, A, b, cones, ncol, n_psd)`` of the analysis at ``pts`` (Clarabel: A z + s = b).

    Columns ``z = [x (nvar), y_k (per_point), Z slacks (bound), t (gamma_cap)]``. Without a cap:
    minimise mu with every LMI <= -eps I; with ``gamma_cap``: maximise t <= 1 with every LMI
    <= -t I and mu <= cap^2. In both, P(rho_k) >= eps I at every point of ``data``, S, R >= eps I.
    ``n_psd`` counts the PSD blocks of the LMIs (and the slack constraints).
    """
    import clarabel

    if rate_form not in RATE_FORMS or coupling not in COUPLINGS:
        raise ValueError(
            f"rate_form={rate_form!r} / coupling={coupling!r} not in {RATE_FORMS} / {COUPLINGS}"
        )
    young = rate_form == "bound" and data.young is not None
    f0, fm, const = point_maps(data, pts, dga_linear=not young)
    big, nvar, n_pd, nloc, ns2 = data.big, data.nvar, data.n_pd, data.nloc, data.ns2
    n_c = data.n_p * ns2
    npt, verts = len(pts), vertices_of(data)
    nsv = big * (big + 1) // 2
    supports = _supports(fm, big) if rate_form == "bound" else []
    if young:  # r (and K if only kappa moves it) has no P-rate or tau term left: no slack
        live = np.any(data.dw_m != 0.0, axis=(0, 1)) | (data.c_tau != 0.0)
        supports = [sup if live[i] else sup[:0] for i, sup in enumerate(supports)]
    z_sizes = [len(s) * (len(s) + 1) // 2 for s in supports]
    nz = sum(z_sizes)
    off_y = nvar
    off_z = off_y + (npt * n_pd if coupling == "per_point" else 0)
    off_e = off_z + npt * nz
    it = off_e + (2 * npt if young else 0)
    with_t = gamma_cap is not None
    ncol = it + int(with_t)
    eye_big = svec_eye(big)
    rows_a: list[sp.csr_matrix] = []
    rows_b: list[Array] = []
    cones: list[Any] = []

    def cols(mat: sp.spmatrix, first: int) -> sp.csr_matrix:  # place mat's columns at `first`
        mat = sp.csr_matrix(mat)
        pad_l, pad_r = first, ncol - first - mat.shape[1]
        return sp.hstack(
            [sp.csr_matrix((mat.shape[0], pad_l)), mat, sp.csr_matrix((mat.shape[0], pad_r))], "csr"
        )

    tail = cols(sp.eye(nloc - n_pd), n_c)  # S, R, mu rows of the local variables
    t_col = cols(sp.csr_matrix(eye_big[:, None]), it) if with_t else None
    b_lmi = -(const + (0.0 if with_t else epsilon) * eye_big)
    if young:  # kappa, r: [[L + sum e_j Phi_j'Phi_j, W_1, W_2], [W', -diag(e_j I)]] <= -eps I
        phi = data.young[1]
        bb = big + 2 * phi.shape[1]
        emb, w_place, e_svec = _young_layout(big, phi)
        wm = young_maps(data, pts)
        eye_bb = svec_eye(bb)
        t_col = cols(sp.csr_matrix(eye_bb[:, None]), it) if with_t else None
        b_lmi = -(const @ emb.T + (0.0 if with_t else epsilon) * eye_bb)
    n_psd = 0
    for q, k in enumerate(pts):
        tk = local_map(data, int(k))
        if coupling == "per_point":
            head = cols(sp.eye(n_pd), off_y + q * n_pd)
            rows_a.append(cols(-tk, 0) + head)
            rows_b.append(np.zeros(n_pd))
            cones.append(clarabel.ZeroConeT(n_pd))
        else:
            head = cols(tk, 0)
        sel = sp.vstack([head, tail], format="csr")  # local variables of point k from z
        if rate_form == "vertex":
            for sig in verts:
                lmi = sp.csr_matrix(f0[q] + np.tensordot(sig, fm[q], axes=(0, 0))) @ sel
                rows_a.append(lmi + t_col if with_t else lmi)
                rows_b.append(b_lmi[q])
                cones.append(clarabel.PSDTriangleConeT(big))
                n_psd += 1
            continue
        lmi = sp.csr_matrix(f0[q]) @ sel
        z0 = off_z + q * nz
        for i, sup in enumerate(supports):
            if len(sup) == 0:
                continue
            sub = _sub_rows(sup, big)
            zcols = z0 + sum(z_sizes[:i])
            lmi = lmi + sp.csr_matrix(
                (np.ones(len(sub)), (sub, zcols + np.arange(len(sub)))), shape=(nsv, ncol)
            )
            m_i = sp.csr_matrix(fm[q, i][sub]) @ sel
            z_i = cols(sp.eye(len(sub)), zcols)
            for sign in (1.0, -1.0):  # Z_i - sign M_i >= 0
                rows_a.append(sign * m_i - z_i)
                rows_b.append(np.zeros(len(sub)))
                cones.append(clarabel.PSDTriangleConeT(len(sup)))
                n_psd += 1
        if young:
            lmi = emb @ lmi
            for j in range(2):
                lmi = lmi + w_place[j] @ sp.csr_matrix(wm[q, j]) @ sel
                lmi = lmi + cols(sp.csr_matrix(e_svec[j][:, None]), off_e + 2 * q + j)
        rows_a.append(lmi + t_col if with_t else lmi)
        rows_b.append(b_lmi[q])
        cones.append(clarabel.PSDTriangleConeT(bb if young else big))
        n_psd += 1
    # P(rho_k) at every point, S and R: >= eps I
    m, n, n2 = data.w_p.shape[0], data.n, 2 * data.n
    tri2, tri1 = svec_of_triu(n2), svec_of_triu(n)
    pmat = sp.block_diag([sp.kron(sp.csr_matrix(data.w_p), tri2), tri1, tri1], format="csr")
    rows_a.append(cols(-pmat, 0))
    rows_b.append(-epsilon * np.concatenate([np.tile(svec_eye(n2), m), svec_eye(n), svec_eye(n)]))
    cones += [clarabel.PSDTriangleConeT(n2)] * m + [clarabel.PSDTriangleConeT(n)] * 2
    q_vec = np.zeros(ncol)
    if with_t:  # mu <= cap^2, t <= 1; maximise t
        rows_a.append(sp.csr_matrix(([1.0, 1.0], ([0, 1], [nvar - 1, it])), shape=(2, ncol)))
        rows_b.append(np.array([float(gamma_cap) ** 2, 1.0]))
        cones.append(clarabel.NonnegativeConeT(2))
        q_vec[it] = -1.0
    else:
        q_vec[nvar - 1] = 1.0
    return q_vec, sp.vstack(rows_a, format="csc"), np.concatenate(rows_b), cones, ncol, n_psd
