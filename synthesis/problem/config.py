"""The design configuration of the LPV synthesis: model, grid, solver settings and the prefilter.

The types here are what every synthesis stage receives; :mod:`pressor.synthesis.problem.config_toml` reads
and validates them from a design TOML file (all physical units, time in s). Any bad value raises
:class:`ConfigError` whose message names the file, the field, the value and the allowed range; the
CLI turns it into exit code 2.

What [box] and [rates] buy: the synthesis certificate (and ``pressor verify``) covers plants whose
(K, T, τ) stay inside the box and change no faster than the rate bounds, with the controller
scheduled on the true ρ. The generated controller clamps its scheduling input to the box and
rate-limits it to the same bounds, so outside them it runs the controller of the nearest admissible
ρ on a plant it was not certified for: no guarantee, only whatever robustness margin the design has
(a patient at K = 0.18 with a box starting at 0.25 sees the K = 0.25 gains, a delay moving at 1 s/s
with a 0.1 s/s bound is tracked late by the controller's delay line).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from pressor.contracts.checks import check_range
from pressor.contracts.drug import DEFAULT_BINDING, DrugBinding
from pressor.synthesis.families.registry import ControllerFamily
from pressor.synthesis.problem.reference import ReferenceConfig

#: Nominal plant the default box must contain: K (mmHg/(ml/h)), T (s), tau (s).
NOMINAL_RHO = (0.55, 150.0, 40.0)


class ConfigError(ValueError):
    """A design configuration value is missing, malformed or out of range.

    The message names the file, the field, the offending value and the allowed range.
    """


def field_error(source: str, fieldname: str, value: Any, allowed: str) -> ConfigError:
    """The error for a bad field: ``<source>: field '<name>' = <value>: must be <allowed>``."""
    return ConfigError(f"{source}: field '{fieldname}' = {value!r}: must be {allowed}")


def field_check(source: str) -> Callable[..., float]:
    """A range check for the fields of ``source``: ``check(fieldname, value, lo, hi, lo_open=False)``
    returns ``value`` as a float in [lo, hi] (``(lo, hi]`` with ``lo_open``), else raises
    :class:`ConfigError` ``<source>: field '<name>' = <value>: must be a finite number in [lo, hi]``
    (:func:`pressor.contracts.checks.check_range`, with the file and field named)."""

    def error(message: str) -> ConfigError:
        return ConfigError(f"{source}: {message}")

    def check(fieldname: str, value: Any, lo: float, hi: float, lo_open: bool = False) -> float:
        return check_range(f"field '{fieldname}'", value, lo, hi, lo_open=lo_open, error=error)

    return check


def check_grid(source: str, fieldname: str, value: Any) -> tuple[int, int, int]:
    """Three grid node counts, each an integer in [2, 15]; :class:`ConfigError` otherwise."""
    if not isinstance(value, list | tuple) or len(value) != 3:
        raise field_error(source, fieldname, value, "a list of 3 integers, each in [2, 15]")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, int) or not 2 <= v <= 15:
            raise field_error(source, fieldname, value, "a list of 3 integers, each in [2, 15]")
        out.append(int(v))
    return tuple(out)  # type: ignore[return-value]


@dataclass(frozen=True)
class PerformanceShaping:
    """Frequency weights of the "shaped" performance output (see :mod:`pressor.synthesis.problem.model`).

    Attributes
    ----------
    e_crossover_rad_s
        ω_b (rad/s): crossover of W_e(s) = (s/M + ω_b)/(s + ω_b A) on the tracking error; with
        γ ≤ 1, |S(jω)| ≲ ω/ω_b below ω_b (the bandwidth demand).
    e_peak
        M > 1: bound on |S| at high frequency (sensitivity peak), with γ ≤ 1.
    e_dc
        A in [0, 1): bound on |S(0)|; 0 makes W_e an integrator realised by x_e (no state).
    u_crossover_rad_s
        ω_u (rad/s): above it the bound on |K S| (infusion per target, (ml/h)/mmHg) falls as ω_u/ω.
    u_dc
        M_u ((ml/h)/mmHg): bound on |K S| below ω_u; must exceed 1/K_min (the static inverse).
    u_hf
        ε_u in [0, M_u): with γ ≤ 1, |K S| ≤ 1/ε_u at high frequency; 0 makes W_u improper
        (realised with du/dt = Ω u_a − Λ u, no state).
    """

    e_crossover_rad_s: float
    e_peak: float
    e_dc: float
    u_crossover_rad_s: float
    u_dc: float
    u_hf: float

    def to_dict(self) -> dict[str, float]:
        """JSON-ready dict."""
        return asdict(self)


@dataclass(frozen=True)
class ModelConfig:
    """What the plant model needs: filter, weights, parameter box, rate bounds, pump limit.

    Attributes
    ----------
    omega, lambda_
        Input filter u = omega/(s + lambda_) u_a, both in 1/s.
    phi
        Weight on the tracking integral x_e in z (1/(mmHg·s)).
    xi
        Weight on the filter input u_a in z ((ml/h)^-1 · ...; dimensionless in practice).
    eta_xe
        Weight of the measurement noise on the x_e channel of y (mmHg·s).
    box
        (3, 2) array, rows K [mmHg/(ml/h)], T [s], tau [s]; columns lower, upper.
    rate_bounds
        (3,) array: |dK/dt| [mmHg/(ml/h)/s], |dT/dt| [s/s], |dtau/dt| [s/s]; with
        ``k_rate_relative`` the first is |d(ln K)/dt| [1/s] instead.
    max_rate_ml_h
        Pump limit (ml/h).
    shaping
        ``None``: the paper's performance output z = [φ x_e; ξ u_a]; otherwise the frequency
        weights of ``weights.performance = "shaped"``.
    k_rate_relative
        False: ``rate_bounds[0]`` bounds |dK/dt| (the box's K moves at most that much per s).
        True: it bounds the *relative* rate |d(ln K)/dt| (1/s), the same at every K: the design
        is certified on a log-K scale, so the K box may span any factor (``[rates]
        K_relative_per_s``; only for the "smith" family, whose controller then also absorbs a
        change of K in its integral, :mod:`pressor.synthesis.families.smith.law`).
    k_rate_up_per_s
        With ``k_rate_relative``: the bound on the *rise* of ln K (1/s), ``rate_bounds[0]`` then
        bounding its fall (``-rate_bounds[0] <= d(ln K)/dt <= k_rate_up_per_s``); None: the same
        bound both ways. A falling K is the benign direction of the certificate's rate terms
        (:mod:`pressor.synthesis.certificates.wirtinger.k_scaling`).
    """

    omega: float
    lambda_: float
    phi: float
    xi: float
    eta_xe: float
    box: np.ndarray
    rate_bounds: np.ndarray
    max_rate_ml_h: float
    shaping: PerformanceShaping | None = None
    k_rate_relative: bool = False
    k_rate_up_per_s: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the artifact's ``model`` metadata entry; ``shaping`` and
        ``k_rate_relative`` only if set, so older artifacts keep their bytes)."""
        out = {
            "omega": self.omega,
            "lambda": self.lambda_,
            "phi": self.phi,
            "xi": self.xi,
            "eta_xe": self.eta_xe,
            "box": np.asarray(self.box, float).tolist(),
            "rate_bounds": np.asarray(self.rate_bounds, float).tolist(),
            "max_rate_ml_h": self.max_rate_ml_h,
        }
        if self.shaping is not None:
            out["shaping"] = self.shaping.to_dict()
        if self.k_rate_relative:
            out["k_rate_relative"] = True
        if self.k_rate_up_per_s is not None:
            out["k_rate_up_per_s"] = float(self.k_rate_up_per_s)
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ModelConfig:
        """Inverse of :meth:`to_dict` (no range validation; the artifact checks shapes)."""
        return cls(
            omega=float(d["omega"]),
            lambda_=float(d["lambda"]),
            phi=float(d["phi"]),
            xi=float(d["xi"]),
            eta_xe=float(d["eta_xe"]),
            box=np.asarray(d["box"], dtype=float).reshape(3, 2),
            rate_bounds=np.asarray(d["rate_bounds"], dtype=float).reshape(3),
            max_rate_ml_h=float(d["max_rate_ml_h"]),
            shaping=(
                PerformanceShaping(**{k: float(v) for k, v in d["shaping"].items()})
                if d.get("shaping") is not None
                else None
            ),
            k_rate_relative=bool(d.get("k_rate_relative", False)),
            k_rate_up_per_s=None
            if d.get("k_rate_up_per_s") is None
            else float(d["k_rate_up_per_s"]),
        )


@dataclass(frozen=True)
class SolverConfig:
    """LMI-solve settings.

    Attributes
    ----------
    lambda2, lambda3
        Fixed slack multipliers of Theorem 3 (dimensionless, in the scaled time unit).
    backoff
        Accept gamma up to (1 + backoff)·gamma* for a better-conditioned solution (0: off).
    epsilon
        Strictness margin of every LMI (scaled units).
    xy_dependence
        "x": X(rho) in the basis, Y constant (rigorous with M = I, see
        :mod:`pressor.synthesis.families.theorem3.lmi`); "constant": X and Y constant; "xy": both in the
        basis (the paper's choice: the congruence step of the proof then does not hold, so only the
        independent verification certifies it).
    time_scale_s
        Time unit of the scaled problem (s).
    rate_terms
        "vertices": the LMI at all 2³ sign combinations of ρ̇ (the paper); "bound": one LMI per node
        with node-local Z_i ⪰ ±∂P̃/∂ρ̂_i (sufficient, 8× fewer large LMIs).
    mean_gamma_weight
        μ ≥ 0: each node has its own level γ_g ≤ γ and the objective is γ + μ·mean(γ_g), which
        also pushes performance at the nodes that are not the worst case (the guarantee stays γ).
    """

    lambda2: float = 1.0
    lambda3: float = 0.5
    backoff: float = 0.0
    epsilon: float = 1e-6
    xy_dependence: str = "x"
    time_scale_s: float = 40.0
    rate_terms: str = "bound"
    mean_gamma_weight: float = 0.0


@dataclass(frozen=True)
class DesignConfig:
    """A full design: model, grid, solver settings, line-search candidates, the prefilter, the
    controller family (:mod:`pressor.synthesis.families.registry`; a family without a synthesis LMI leaves
    the solver settings but ``time_scale_s`` unused), the drug and syringe concentration its
    gains are for (:class:`pressor.contracts.drug.DrugBinding`) and, optionally, the sensitivity range of
    the patients it is for in mmHg per µg/kg/min (``population``, the cautious start's prior)."""

    model: ModelConfig
    grid_points: tuple[int, int, int]
    solver: SolverConfig
    reference: ReferenceConfig = field(default_factory=ReferenceConfig)
    controller: ControllerFamily = field(default_factory=ControllerFamily)
    lambda2_candidates: tuple[float, ...] = (0.5, 1.0, 2.0)
    lambda3_candidates: tuple[float, ...] = (0.25, 0.5, 1.0)
    drug: DrugBinding = DEFAULT_BINDING
    population: tuple[float, float] | None = None
    source: str = "<default>"
    raw: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)

    def grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The synthesis grid in physical units: evenly spaced nodes over each box edge."""
        box = self.model.box
        return tuple(np.linspace(box[i, 0], box[i, 1], self.grid_points[i]) for i in range(3))  # type: ignore[return-value]

    def with_grid(self, points: tuple[int, int, int]) -> DesignConfig:
        """Copy with another grid (validated)."""
        check_grid(self.source, "grid.points", list(points))
        return replace(self, grid_points=tuple(int(p) for p in points))  # type: ignore[arg-type]

    def with_lambdas(self, lambda2: float, lambda3: float) -> DesignConfig:
        """Copy with other fixed (lambda2, lambda3)."""
        check = field_check(self.source)
        check("solver.lambda2", lambda2, 1e-4, 1e4)
        check("solver.lambda3", lambda3, 1e-4, 1e4)
        return replace(self, solver=replace(self.solver, lambda2=lambda2, lambda3=lambda3))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of the full design (stored in the artifact; ``controller`` only for a
        family other than the default one, so artifacts of that family keep their bytes; ``drug``
        always)."""
        out = {
            "model": self.model.to_dict(),
            "grid_points": list(self.grid_points),
            "solver": asdict(self.solver),
            "line_search": {
                "lambda2": list(self.lambda2_candidates),
                "lambda3": list(self.lambda3_candidates),
            },
            "reference": self.reference.to_dict(),
            "drug": self.drug.to_dict(),
        }
        if not self.controller.is_default:
            out["controller"] = self.controller.to_dict()
        if self.population is not None:
            out["population"] = {"K_ug_kg_min": list(self.population)}
        return out
