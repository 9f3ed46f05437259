"""Theorem 3 of the paper as a batched LMI problem (cvxpy, solved by Clarabel).

Derivation (checked here, since the printed theorem has errors)
--------------------------------------------------------------
Lyapunov–Krasovskii functional for the closed loop ``ẋ = A x + Ad x(t−τ) + B w``::

    V = xᵀP(ρ)x + ∫_{t−τ}^{t} xᵀQx ds + τ̄ ∫_{−τ̄}^{0}∫_{t+θ}^{t} ẋᵀRẋ ds dθ

With Jensen's inequality ``−τ̄∫_{t−τ}^{t}ẋᵀRẋ ≤ −(x − x_τ)ᵀR(x − x_τ)`` (τ ≤ τ̄) the condition
``V̇ + zᵀz/γ − γwᵀw < 0`` is a quadratic form in ``ζ = [ẋ; x; x_τ; w]`` that must be negative on
``[−I, A, Ad, B] ζ = 0``. Finsler's lemma with the slack ``[V1; λ2 V1; λ3 V1; 0]`` and a Schur
complement on z gives the 5-block analysis LMI (symmetric, ``He(M) = M + Mᵀ``)::

    [ τ̄²R − 2V1     P − λ2V1 + V1A      −λ3V1 + V1Ad              V1B      0   ]
    [      ⋆       Ṗ+Q−R + λ2He(V1A)   R + λ2V1Ad + λ3AᵀV1        λ2V1B    Cᵀ  ]
    [      ⋆            ⋆        −(1−τ̇)Q − R + λ3He(V1Ad)       λ3V1B    Cdᵀ ]  ≺ 0
    [      ⋆            ⋆               ⋆                          −γI     Dᵀ  ]
    [      ⋆            ⋆               ⋆                           ⋆     −γI  ]

For synthesis take V1 = 𝒳 = [[X, N], [Nᵀ, ⋆]] with 𝒳⁻¹ = [[Y, M], [Mᵀ, ⋆]], Π1 = [[Y, I], [Mᵀ, 0]]
and the congruence diag(Π1, Π1, Π1, I, I). Then Π1ᵀ𝒳Π1 = Ṽ = [[Y, I], [I, X]], Π1ᵀ𝒳A_clΠ1 = 𝒜,
Π1ᵀ𝒳B_cl = 𝓑, C_clΠ1 = 𝒞 (the paper's linearising change of variables), and P̃, Q̃, R̃ = Π1ᵀ(·)Π1,
all **2n×2n** (the printed n×n is an erratum). This is Theorem 3 with the τ̄²R̃ term in block (1,1)
instead of the printed 6th block row/column; the printed 6-block form is not what Finsler gives and
was measured to be far more conservative (γ 23.6 vs 8.5 on the same grid).

Which guarantee the controller carries (deviation from the paper)
-----------------------------------------------------------------
The congruence carries a *constant* Q̃, R̃ and ``∂P̃/∂ρ`` back to the closed loop only if Π1 is
constant, i.e. Y and M constant. The paper lets X and Y both depend on ρ; that breaks the proof for
time-varying ρ (for each *frozen* ρ the congruence is still exact). Three options
(``solver.xy_dependence``):

* ``"x"`` — **Y constant, X(ρ) in the basis** (**the shipped default**), factorisation ``M = I,
  N = I − X(ρ)Y`` (smooth, no SVD): Π1 is constant, the slack 𝒳(ρ) may vary freely (Finsler needs
  no derivative of it), so the rate-bounded L2-gain bound γ holds as written (γ ≈ 13.5 on 3×3×3).
  Independently, :mod:`pressor.synthesis.verification.verify` certifies the reconstructed closed loop with
  the Theorem-1 analysis LMI (P quadratic in ρ, all rate vertices) on the 5×5×5 grid incl. cell
  midpoints, re-checked in floating point. Cost: a slow nominal step (overshoot ≈ 1.9 %, settling ≈
  465 s, slower than the PI's 418.8 s); ξ (0.015–0.12), φ, η and λ did not speed it up (φ only
  scales γ) — the paper's claim (< 1 %, < 200 s) is not reproduced by a verified design.
* ``"constant"`` — X and Y constant: rigorous, no better than "x" here.
* ``"xy"`` — both in the basis (as in the paper): γ ≈ 5, nominal step 0.4 % /
  ≈ 227 s. What it carries: at every synthesis node the frozen closed loop satisfies the
  delay-dependent L2-gain LMI; the rate-bounded claim between nodes does **not** follow, and the
  independent analysis LMI on the 5×5×5 grid fails for it (best common margin −0.0013, 104/125
  points fail the re-check), so it is not shipped.

Between grid nodes nothing is certified by the synthesis itself;
:func:`research.synthesis_forms.theorem3_certificate.certificate_margins` evaluates the synthesis
certificate at arbitrary points.

Other choices
-------------
* Rate terms, ``rate_terms = "vertices"`` (the paper): the LMI is affine in ρ̇, so it is imposed at
  all 2³ sign combinations (±νi) at each grid node; the τ̇ in Ξ22 is the same ρ̇3 as in ∂P̃/∂ρ3 (τ
  is the third parameter, ∂τ/∂ρ3 = 1). ``rate_terms = "bound"`` (default, faster): node-local
  symmetric Z_{g,i} with Z_{g,i} ⪰ ±∂P̃/∂ρ̂_i(ρ_g) and ``Ṗ`` replaced by Σ_i ν̂_i Z_{g,i}, which
  bounds every vertex from above; ``−(1 − τ̇)Q̃`` is largest at τ̇ = +ν_τ because Q̃ ⪰ 0. This
  implies the vertex conditions (sufficient, slightly more conservative) with one large LMI per node
  instead of eight.
* Strict inequalities become ``⪯ −εI`` / ``⪰ εI``.
* λ2, λ3 are fixed (line search in :mod:`pressor.synthesis.families.theorem3.line_search`), making the
  problem an SDP.
* Everything is in the scaled coordinates of :mod:`pressor.synthesis.problem.scaling`.

Build
-----
The LMI is one numeric function of the decision vector, vectorised over grid points and rate
vertices (:func:`lmi_blocks`). Because it is affine, evaluating it at 0 and at unit vectors (in
chunks) gives its exact sparse affine map ``vec F(x) = F0 + A x``; cvxpy receives that as a single
batched PSD constraint ``reshape(b − A x, (N, m, m)) ⪰ 0`` and compiles in well under a second
(:mod:`pressor.synthesis.families.theorem3.lmi_solve`); the decision vector's layout is
:mod:`pressor.synthesis.families.theorem3.lmi_layout`.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from pressor.synthesis.families.theorem3.lmi_layout import Layout
from pressor.synthesis.problem import basis
from pressor.synthesis.problem.config import DesignConfig
from pressor.synthesis.problem.model import N_STATE, dims, plant_batch
from pressor.synthesis.problem.scaling import Scaling

N2 = 2 * N_STATE  # closed-loop order of the shipped ("integral") plant


@dataclass(frozen=True)
class Problem:
    """The numeric data of one synthesis problem (scaled coordinates)."""

    cfg: DesignConfig
    scaling: Scaling
    layout: Layout
    rho: np.ndarray  # (G, 3) physical grid nodes
    rho_hat: np.ndarray  # (G, 3)
    plant: dict[str, np.ndarray]  # scaled, (G, r, c)
    weights: np.ndarray  # (G, nb)
    dweights: np.ndarray  # (G, 3, nb)
    vertices: np.ndarray  # (V, 3) signs
    nu_hat: np.ndarray  # (3,) bounds on |dρ̂/dt̂|
    nu_tau: float  # bound on |dτ/dt| (dimensionless)
    tau_bar_hat: float  # max delay in scaled time

    @property
    def size(self) -> int:
        """Order m of each synthesis LMI."""
        return 6 * self.layout.n + self.plant["B1"].shape[-1] + self.plant["C1"].shape[-2]


def make_problem(cfg: DesignConfig, rho: np.ndarray | None = None) -> Problem:
    """Set up the scaled problem on ``cfg``'s grid (or on the given (G, 3) physical points)."""
    d = dims(cfg.model)
    sc = Scaling.for_box(cfg.model.box, cfg.solver.time_scale_s, d.n)
    if rho is None:
        g = cfg.grid()
        rho = np.array(list(itertools.product(*g)), dtype=float)
    rho = np.atleast_2d(np.asarray(rho, dtype=float))
    rho_hat = sc.to_hat(rho)
    plant = sc.plant(plant_batch(rho, cfg.model))
    return Problem(
        cfg=cfg,
        scaling=sc,
        layout=Layout(cfg.solver.xy_dependence, cfg.solver.rate_terms, rho.shape[0], d),
        rho=rho,
        rho_hat=rho_hat,
        plant=plant,
        weights=basis.basis_weights(rho_hat),
        dweights=basis.basis_derivatives(rho_hat),
        vertices=np.array(list(itertools.product((-1.0, 1.0), repeat=3))),
        nu_hat=sc.rate_hat(cfg.model.rate_bounds),
        nu_tau=float(cfg.model.rate_bounds[2]),
        tau_bar_hat=float(cfg.model.box[2, 1] / sc.time_s),
    )


def _ev(c: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Coefficients (J, nb, r, c) at weights (G, nb) -> (J, G, r, c)."""
    if c.shape[1] == 1:
        return np.broadcast_to(c[:, :1], (c.shape[0], w.shape[0], *c.shape[2:]))
    return np.einsum("gb,jbrc->jgrc", w, c)


def _t(m: np.ndarray) -> np.ndarray:
    return np.swapaxes(m, -1, -2)


def lmi_blocks(prob: Problem, vals: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The transformed closed-loop quantities of Theorem 3 at every grid node.

    Parameters
    ----------
    prob
        The problem.
    vals
        Decision coefficients, name -> (J, nb, r, c).

    Returns
    -------
    dict
        ``V, A, Ad, B, C, Cd, D, P, Q, R`` (J, G, ·, ·) and ``dP`` (J, G, 3, 2n, 2n).
    """
    p, w = prob.plant, prob.weights
    X = _ev(vals["X"], w)
    Y = _ev(vals["Y"], w)
    Ah, Adh, Bh = _ev(vals["Ah"], w), _ev(vals["Adh"], w), _ev(vals["Bh"], w)
    Ch, Cdh, Dk = _ev(vals["Ch"], w), _ev(vals["Cdh"], w), _ev(vals["Dk"], w)
    A, Ad, B1, B2 = p["A"], p["Ad"], p["B1"], p["B2"]
    C1, C1d, C2, C2d = p["C1"], p["C1d"], p["C2"], p["C2d"]
    D11, D12, D21 = p["D11"], p["D12"], p["D21"]
    j, g = X.shape[0], w.shape[0]
    n = X.shape[-1]
    eye = np.broadcast_to(np.eye(n), (j, g, n, n))
    B2Dk = B2 @ Dk

    def cat(a, b, c, d):
        return np.concatenate(
            [np.concatenate([a, b], axis=-1), np.concatenate([c, d], axis=-1)], axis=-2
        )

    V = cat(Y, eye, eye, X)
    cA = cat(A @ Y + B2 @ Ch, A + B2Dk @ C2, Ah, X @ A + Bh @ C2)
    cAd = cat(Ad @ Y + B2 @ Cdh, Ad + B2Dk @ C2d, Adh, X @ Ad + Bh @ C2d)
    cB = np.concatenate([B1 + B2Dk @ D21, X @ B1 + Bh @ D21], axis=-2)
    cC = np.concatenate([C1 @ Y + D12 @ Ch, C1 + D12 @ Dk @ C2], axis=-1)
    cCd = np.concatenate([C1d @ Y + D12 @ Cdh, C1d + D12 @ Dk @ C2d], axis=-1)
    cD = D11 + D12 @ Dk @ D21
    P = _ev(vals["P"], w)
    dP = np.einsum("gib,jbrc->jgirc", prob.dweights, vals["P"])
    Q = _ev(vals["Q"], w)
    R = _ev(vals["R"], w)
    return {
        "V": V,
        "A": cA,
        "Ad": cAd,
        "B": cB,
        "C": cC,
        "Cd": cCd,
        "D": cD,
        "P": P,
        "dP": dP,
        "Q": Q,
        "R": R,
        "gamma": vals["gnode"][:, :, 0, 0],
    }


def assemble(
    V: np.ndarray,
    P: np.ndarray,
    Pdot: np.ndarray,
    Q: np.ndarray,
    R: np.ndarray,
    A: np.ndarray,
    Ad: np.ndarray,
    B: np.ndarray,
    C: np.ndarray,
    Cd: np.ndarray,
    D: np.ndarray,
    gamma: np.ndarray,
    taudot: np.ndarray,
    tau_bar: float,
    lambda2: float,
    lambda3: float,
) -> np.ndarray:
    """The 5-block analysis matrix (see module docstring) for batched arguments.

    Every matrix argument has the same leading batch shape ``S``; ``gamma`` and ``taudot`` have
    shape ``S``. ``V`` plays the slack V1 (𝒳 or Ṽ) and ``A``… the products V1·A (𝒜) etc.:
    the caller passes ``VA = V1 A`` in ``A``, ``VAd`` in ``Ad`` and ``VB`` in ``B``.

    Returns
    -------
    numpy.ndarray
        Shape ``S + (m, m)`` with m = 3·n2 + nw + nz; the condition is ``F ≺ 0``.
    """
    n2 = V.shape[-1]
    nw = B.shape[-1]
    nz = C.shape[-2]
    s = np.broadcast_shapes(
        V.shape[:-2], P.shape[:-2], Pdot.shape[:-2], A.shape[:-2], gamma.shape, taudot.shape
    )
    g = gamma[..., None, None]
    td = taudot[..., None, None]
    m = 3 * n2 + nw + nz
    F = np.zeros((*s, m, m))
    i1, i2, i3, i4, i5 = (
        slice(0, n2),
        slice(n2, 2 * n2),
        slice(2 * n2, 3 * n2),
        slice(3 * n2, 3 * n2 + nw),
        slice(3 * n2 + nw, m),
    )
    F[..., i1, i1] = tau_bar**2 * R - 2.0 * V
    F[..., i1, i2] = P - lambda2 * V + A
    F[..., i1, i3] = -lambda3 * V + Ad
    F[..., i1, i4] = B
    F[..., i2, i2] = Pdot + Q - R + lambda2 * (A + _t(A))
    F[..., i2, i3] = R + lambda3 * _t(A) + lambda2 * Ad
    F[..., i2, i4] = lambda2 * B
    F[..., i2, i5] = _t(C)
    F[..., i3, i3] = -(1.0 - td) * Q - R + lambda3 * (Ad + _t(Ad))
    F[..., i3, i4] = lambda3 * B
    F[..., i3, i5] = _t(Cd)
    F[..., i4, i4] = -g * np.eye(nw)
    F[..., i4, i5] = _t(D)
    F[..., i5, i5] = -g * np.eye(nz)
    # fill the lower triangle
    iu = np.triu_indices(m, 1)
    F[..., iu[1], iu[0]] = F[..., iu[0], iu[1]]
    return F


def synthesis_lmi(prob: Problem, vals: dict[str, np.ndarray]) -> np.ndarray:
    """Theorem 3 (5-block form) at every grid node and rate vertex.

    Returns
    -------
    numpy.ndarray
        (J, G, V, m, m); the condition is ``F ≺ 0``.
    """
    blk = lmi_blocks(prob, vals)
    if prob.cfg.solver.rate_terms == "bound":
        # one LMI per node: Ṗ ⪯ Σ_i ν̂_i Z_{g,i}; −(1 − τ̇)Q̃ is largest at τ̇ = +ν_τ (Q̃ ⪰ 0)
        verts = np.ones((1, 3))
        j, n2 = blk["V"].shape[0], blk["V"].shape[-1]
        z = vals["Z"].reshape(j, -1, 3, n2, n2)
        pdot = np.einsum("i,jgirc->jgrc", prob.nu_hat, z)[:, :, None]
    else:
        verts = prob.vertices  # (V, 3)
        # Ṗ at each vertex: Σ_i s_i ν̂_i ∂P̃/∂ρ̂_i  -> (J, G, V, n2, n2)
        pdot = np.einsum("vi,i,jgirc->jgvrc", verts, prob.nu_hat, blk["dP"])
    taudot = verts[:, 2] * prob.nu_tau  # (V,)

    def e(a):
        return a[:, :, None]

    j, g = blk["V"].shape[:2]
    nv = verts.shape[0]
    gam = np.broadcast_to(blk["gamma"][:, :, None], (j, g, nv))
    td = np.broadcast_to(taudot[None, None, :], (j, g, nv))
    return assemble(
        e(blk["V"]),
        e(blk["P"]),
        pdot,
        e(blk["Q"]),
        e(blk["R"]),
        e(blk["A"]),
        e(blk["Ad"]),
        e(blk["B"]),
        e(blk["C"]),
        e(blk["Cd"]),
        e(blk["D"]),
        gam,
        td,
        prob.tau_bar_hat,
        prob.cfg.solver.lambda2,
        prob.cfg.solver.lambda3,
    )


def positivity(prob: Problem, vals: dict[str, np.ndarray]) -> np.ndarray:
    """Matrices that must be ≻ 0: P̃ at every node, Q̃, R̃ (and Z ∓ ∂P̃ in "bound" mode).

    Shape (J, k, 2n, 2n).
    """
    P = _ev(vals["P"], prob.weights)
    Q = vals["Q"][:, :1]
    R = vals["R"][:, :1]
    parts = [P, Q, R]
    if prob.cfg.solver.rate_terms == "bound":
        j, n2 = P.shape[0], P.shape[-1]
        dP = np.einsum("gib,jbrc->jgirc", prob.dweights, vals["P"])
        z = vals["Z"].reshape(j, -1, 3, n2, n2)
        parts += [(z - dP).reshape(j, -1, n2, n2), (z + dP).reshape(j, -1, n2, n2)]
    return np.concatenate(parts, axis=1)


def affine_map(
    prob: Problem, fn: Callable[[Problem, dict[str, np.ndarray]], np.ndarray], chunk: int = 64
) -> tuple[sp.csr_matrix, np.ndarray, tuple[int, ...]]:
    """Exact sparse affine map of an affine matrix function of the decision vector.

    Returns ``(A, b, shape)`` with ``fn(x).reshape(-1) == A @ x + b`` and ``shape`` the shape of
    ``fn`` for one vector.
    """
    lay = prob.layout
    f0 = fn(prob, lay.unpack(np.zeros((1, lay.nvar))))[0]
    shape = f0.shape
    b = f0.reshape(-1)
    rows, cols, data = [], [], []
    for start in range(0, lay.nvar, chunk):
        stop = min(lay.nvar, start + chunk)
        e = np.zeros((stop - start, lay.nvar))
        e[np.arange(stop - start), np.arange(start, stop)] = 1.0
        d = fn(prob, lay.unpack(e)).reshape(stop - start, -1) - b[None, :]
        jj, rr = np.nonzero(np.abs(d) > 1e-13)
        rows.append(rr)
        cols.append(jj + start)
        data.append(d[jj, rr])
    A = sp.csr_matrix(
        (np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))),
        shape=(b.size, lay.nvar),
    )
    return A, b, shape


def max_eig(prob: Problem, x: np.ndarray) -> tuple[float, float]:
    """Largest eigenvalue of the synthesis LMI and smallest of the positivity set at a solution."""
    vals = prob.layout.unpack(x[None, :])
    F = synthesis_lmi(prob, vals)
    Pm = positivity(prob, vals)
    return float(np.linalg.eigvalsh(F).max()), float(np.linalg.eigvalsh(Pm).min())
