"""Validated design configuration (TOML) for the LPV synthesis.

A design is described by a TOML file with the sections below (all physical units, time in s)::

    [box]        K = [lo, hi]  (mmHg/(ml/h)),  T_s = [lo, hi] (s),  tau_s = [lo, hi] (s)
    [rates]      K_per_s (mmHg/(ml/h)/s),  T_s_per_s (s/s),  tau_s_per_s (s/s, < 1)
    [filter]     omega (1/s), lambda (1/s)            u = omega/(s + lambda) u_a
    [weights]    phi (1/(mmHg·s)) on x_e,  xi on u_a,  eta_xe (mmHg·s) x_e measurement-noise weight,
                 performance ("integral" | "shaped") and, for "shaped", the frequency weights
                 e_crossover_rad_s (ω_b), e_peak (M), e_dc (A) of W_e(s) = (s/M + ω_b)/(s + ω_b A)
                 on the tracking error and u_crossover_rad_s (ω_u), u_dc (M_u, (ml/h)/mmHg),
                 u_hf (ε_u) of W_u(s) = (s + ω_u/M_u)/(ε_u s + ω_u) on the infusion
                 (see :mod:`synthesis.model`; optional keys, defaults in ``SHAPING_DEFAULTS``)
    [grid]       points = [nK, nT, ntau]              synthesis grid (each >= 2)
    [solver]     lambda2, lambda3 (scaled-time slack multipliers), backoff (fraction, >= 0),
                 epsilon (strictness margin), xy_dependence ("constant" | "x" | "xy"),
                 time_scale_s (the time unit of the scaled problem), rate_terms
                 ("vertices" | "bound"), mean_gamma_weight
    [line_search] lambda2 = [...], lambda3 = [...]   candidate values for ``--lambda-search``
    [pump]       max_rate_ml_h
    [reference]  enabled (bool), lambda_s (s, in [1, 1000]), pump_fraction (in [0.1, 1]),
                 k_min (mmHg/(ml/h), in [0.001, box K upper])
                 the two-degree-of-freedom prefilter of :mod:`synthesis.reference` (outside the
                 certified loop: it changes the reference and adds a feedforward, not the LMIs)

What [box] and [rates] buy: the synthesis certificate (and ``pressor verify``) covers plants whose
(K, T, τ) stay inside the box and change no faster than the rate bounds, with the controller
scheduled on the true ρ. The generated controller clamps its scheduling input to the box and
rate-limits it to the same bounds, so outside them it runs the controller of the nearest admissible
ρ on a plant it was not certified for: no guarantee, only whatever robustness margin the design has
(a patient at K = 0.18 with a box starting at 0.25 sees the K = 0.25 gains, a delay moving at 1 s/s
with a 0.1 s/s bound is tracked late by the controller's delay line).

Every missing key takes the shipped default (``synthesis/data/default_design.toml``). Any bad
value raises :class:`ConfigError` whose message names the file, the field, the value and the
allowed range; the CLI turns it into exit code 2.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import asdict, dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from synthesis.reference import K_MIN_RANGE, LAMBDA_RANGE_S, PUMP_FRACTION_RANGE, ReferenceConfig

#: Nominal plant the default box must contain (DESIGN.md §4).
NOMINAL_RHO = (0.55, 150.0, 40.0)

PARAM_NAMES = ("K", "T_s", "tau_s")
RATE_NAMES = ("K_per_s", "T_s_per_s", "tau_s_per_s")

#: Allowed ranges: (lo, hi) for box edges, rates, filter, weights.
_BOX_RANGE = {"K": (1e-3, 10.0), "T_s": (1.0, 2000.0), "tau_s": (0.0, 600.0)}
_RATE_RANGE = {"K_per_s": (0.0, 1.0), "T_s_per_s": (0.0, 10.0), "tau_s_per_s": (0.0, 0.999)}


#: Optional [weights] keys (not in the shipped TOML, whose design uses performance = "integral").
SHAPING_DEFAULTS: dict[str, Any] = {
    "performance": "integral",
    "e_crossover_rad_s": 0.005,
    "e_peak": 2.0,
    "e_dc": 0.0,
    "u_crossover_rad_s": 0.05,
    "u_dc": 20.0,
    "u_hf": 0.0,
}


class ConfigError(ValueError):
    """A design configuration value is missing, malformed or out of range.

    The message names the file, the field, the offending value and the allowed range.
    """


@dataclass(frozen=True)
class PerformanceShaping:
    """Frequency weights of the "shaped" performance output (see :mod:`synthesis.model`).

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
        (3,) array: |dK/dt| [mmHg/(ml/h)/s], |dT/dt| [s/s], |dtau/dt| [s/s].
    max_rate_ml_h
        Pump limit (ml/h).
    shaping
        ``None``: the paper's performance output z = [φ x_e; ξ u_a]; otherwise the frequency
        weights of ``weights.performance = "shaped"``.
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

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the artifact's ``model`` metadata entry; ``shaping`` only if set)."""
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
        "x": X(rho) in the basis, Y constant (rigorous with M = I, see :mod:`synthesis.lmi`);
        "constant": X and Y constant; "xy": both in the basis (the paper's choice: the congruence
        step of the proof then does not hold, so only the independent verification certifies it).
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
    """A full design: model, grid, solver settings, line-search candidates and the prefilter."""

    model: ModelConfig
    grid_points: tuple[int, int, int]
    solver: SolverConfig
    reference: ReferenceConfig = field(default_factory=ReferenceConfig)
    lambda2_candidates: tuple[float, ...] = (0.5, 1.0, 2.0)
    lambda3_candidates: tuple[float, ...] = (0.25, 0.5, 1.0)
    source: str = "<default>"
    raw: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)

    def grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The synthesis grid in physical units: evenly spaced nodes over each box edge."""
        box = self.model.box
        return tuple(np.linspace(box[i, 0], box[i, 1], self.grid_points[i]) for i in range(3))  # type: ignore[return-value]

    def with_grid(self, points: tuple[int, int, int]) -> DesignConfig:
        """Copy with another grid (validated)."""
        _check_grid(self.source, "grid.points", list(points))
        return replace(self, grid_points=tuple(int(p) for p in points))  # type: ignore[arg-type]

    def with_lambdas(self, lambda2: float, lambda3: float) -> DesignConfig:
        """Copy with other fixed (lambda2, lambda3)."""
        _check_range(self.source, "solver.lambda2", lambda2, 1e-4, 1e4)
        _check_range(self.source, "solver.lambda3", lambda3, 1e-4, 1e4)
        return replace(self, solver=replace(self.solver, lambda2=lambda2, lambda3=lambda3))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of the full design (stored in the artifact)."""
        return {
            "model": self.model.to_dict(),
            "grid_points": list(self.grid_points),
            "solver": asdict(self.solver),
            "line_search": {
                "lambda2": list(self.lambda2_candidates),
                "lambda3": list(self.lambda3_candidates),
            },
            "reference": self.reference.to_dict(),
        }


def default_config_path() -> Path:
    """Path of the shipped default design TOML."""
    return Path(str(resources.files("synthesis") / "data" / "default_design.toml"))


def _fail(source: str, fieldname: str, value: Any, allowed: str) -> ConfigError:
    return ConfigError(f"{source}: field '{fieldname}' = {value!r}: must be {allowed}")


def _number(source: str, fieldname: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _fail(source, fieldname, value, "a number")
    v = float(value)
    if not math.isfinite(v):
        raise _fail(source, fieldname, value, "a finite number")
    return v


def _check_range(source: str, fieldname: str, value: Any, lo: float, hi: float) -> float:
    v = _number(source, fieldname, value)
    if not lo <= v <= hi:
        raise _fail(source, fieldname, value, f"in [{lo:g}, {hi:g}]")
    return v


def _check_pos(source: str, fieldname: str, value: Any, hi: float) -> float:
    v = _number(source, fieldname, value)
    if not 0.0 < v <= hi:
        raise _fail(source, fieldname, value, f"in (0, {hi:g}]")
    return v


def _check_grid(source: str, fieldname: str, value: Any) -> tuple[int, int, int]:
    if not isinstance(value, list | tuple) or len(value) != 3:
        raise _fail(source, fieldname, value, "a list of 3 integers, each in [2, 15]")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, int) or not 2 <= v <= 15:
            raise _fail(source, fieldname, value, "a list of 3 integers, each in [2, 15]")
        out.append(int(v))
    return tuple(out)  # type: ignore[return-value]


def _get(table: dict[str, Any], section: str, key: str, default: dict[str, Any]) -> Any:
    sec = table.get(section, {})
    if key in sec:
        return sec[key]
    return default.get(section, {}).get(key)


def _merge_check_keys(source: str, table: dict[str, Any], default: dict[str, Any]) -> None:
    """Unknown sections/keys are errors (a typo must not silently fall back to a default)."""
    default = {**default, "weights": {**default.get("weights", {}), **SHAPING_DEFAULTS}}
    for section, body in table.items():
        if section not in default:
            raise _fail(source, section, "<section>", f"one of {sorted(default)}")
        if not isinstance(body, dict):
            raise _fail(source, section, body, "a TOML table")
        for key in body:
            if key not in default[section]:
                raise _fail(
                    source, f"{section}.{key}", body[key], f"one of {sorted(default[section])}"
                )


def parse_config(table: dict[str, Any], source: str = "<config>") -> DesignConfig:
    """Validate a parsed TOML table (missing keys take the shipped defaults).

    Parameters
    ----------
    table
        The parsed TOML document.
    source
        File name used in error messages.

    Raises
    ------
    ConfigError
        On any unknown key or out-of-range value.
    """
    with open(default_config_path(), "rb") as fh:
        default = tomllib.load(fh)
    _merge_check_keys(source, table, default)

    box = np.zeros((3, 2))
    for i, name in enumerate(PARAM_NAMES):
        f = f"box.{name}"
        val = _get(table, "box", name, default)
        if not isinstance(val, list | tuple) or len(val) != 2:
            raise _fail(source, f, val, "a list [lower, upper]")
        lo_ok, hi_ok = _BOX_RANGE[name]
        lo = _check_range(source, f, val[0], lo_ok, hi_ok)
        hi = _check_range(source, f, val[1], lo_ok, hi_ok)
        if not lo < hi:
            raise _fail(source, f, val, "a list [lower, upper] with lower < upper")
        box[i] = (lo, hi)
    if box[1, 0] <= 0.0:
        raise _fail(source, "box.T_s", box[1].tolist(), "positive")

    rates = np.zeros(3)
    for i, name in enumerate(RATE_NAMES):
        lo, hi = _RATE_RANGE[name]
        rates[i] = _check_range(
            source, f"rates.{name}", _get(table, "rates", name, default), lo, hi
        )

    omega = _check_pos(source, "filter.omega", _get(table, "filter", "omega", default), 100.0)
    lam = _check_pos(source, "filter.lambda", _get(table, "filter", "lambda", default), 100.0)
    phi = _check_pos(source, "weights.phi", _get(table, "weights", "phi", default), 1e3)
    xi = _check_pos(source, "weights.xi", _get(table, "weights", "xi", default), 1e3)
    eta = _check_pos(source, "weights.eta_xe", _get(table, "weights", "eta_xe", default), 1e6)
    shaping = _parse_shaping(table, source)
    pump = _check_pos(
        source, "pump.max_rate_ml_h", _get(table, "pump", "max_rate_ml_h", default), 1e4
    )
    grid = _check_grid(source, "grid.points", _get(table, "grid", "points", default))

    l2 = _check_range(
        source, "solver.lambda2", _get(table, "solver", "lambda2", default), 1e-4, 1e4
    )
    l3 = _check_range(
        source, "solver.lambda3", _get(table, "solver", "lambda3", default), 1e-4, 1e4
    )
    backoff = _check_range(
        source, "solver.backoff", _get(table, "solver", "backoff", default), 0.0, 1.0
    )
    eps = _check_range(
        source, "solver.epsilon", _get(table, "solver", "epsilon", default), 0.0, 1e-2
    )
    xy = _get(table, "solver", "xy_dependence", default)
    if xy not in ("constant", "x", "xy"):
        raise _fail(source, "solver.xy_dependence", xy, "one of 'constant', 'x', 'xy'")
    ts = _check_pos(
        source, "solver.time_scale_s", _get(table, "solver", "time_scale_s", default), 1e4
    )
    mgw = _check_range(
        source,
        "solver.mean_gamma_weight",
        _get(table, "solver", "mean_gamma_weight", default),
        0.0,
        1e3,
    )
    rt = _get(table, "solver", "rate_terms", default)
    if rt not in ("vertices", "bound"):
        raise _fail(source, "solver.rate_terms", rt, "one of 'vertices', 'bound'")

    cands = []
    for key in ("lambda2", "lambda3"):
        f = f"line_search.{key}"
        val = _get(table, "line_search", key, default)
        if not isinstance(val, list | tuple) or not 1 <= len(val) <= 20:
            raise _fail(source, f, val, "a list of 1 to 20 numbers in [1e-4, 1e4]")
        cands.append(tuple(_check_range(source, f, v, 1e-4, 1e4) for v in val))

    enabled = _get(table, "reference", "enabled", default)
    if not isinstance(enabled, bool):
        raise _fail(source, "reference.enabled", enabled, "true or false")
    reference = ReferenceConfig(
        enabled=enabled,
        lambda_s=_check_range(
            source,
            "reference.lambda_s",
            _get(table, "reference", "lambda_s", default),
            *LAMBDA_RANGE_S,
        ),
        pump_fraction=_check_range(
            source,
            "reference.pump_fraction",
            _get(table, "reference", "pump_fraction", default),
            *PUMP_FRACTION_RANGE,
        ),
        k_min=_check_range(
            source,
            "reference.k_min",
            _get(table, "reference", "k_min", default),
            K_MIN_RANGE[0],
            min(K_MIN_RANGE[1], float(box[0, 1])),
        ),
    )

    model = ModelConfig(
        omega=omega,
        lambda_=lam,
        phi=phi,
        xi=xi,
        eta_xe=eta,
        box=box,
        rate_bounds=rates,
        max_rate_ml_h=pump,
        shaping=shaping,
    )
    solver = SolverConfig(
        lambda2=l2,
        lambda3=l3,
        backoff=backoff,
        epsilon=eps,
        xy_dependence=xy,
        time_scale_s=ts,
        rate_terms=rt,
        mean_gamma_weight=mgw,
    )
    return DesignConfig(
        model=model,
        grid_points=grid,
        solver=solver,
        reference=reference,
        lambda2_candidates=cands[0],
        lambda3_candidates=cands[1],
        source=source,
        raw=table,
    )


def _parse_shaping(table: dict[str, Any], source: str) -> PerformanceShaping | None:
    """The [weights] frequency-shaping keys (validated even when ``performance = "integral"``)."""
    sec = table.get("weights", {})

    def get(key: str) -> Any:
        return sec.get(key, SHAPING_DEFAULTS[key])

    mode = get("performance")
    if mode not in ("integral", "shaped"):
        raise _fail(source, "weights.performance", mode, "one of 'integral', 'shaped'")
    wb = _check_pos(source, "weights.e_crossover_rad_s", get("e_crossover_rad_s"), 10.0)
    m = _check_range(source, "weights.e_peak", get("e_peak"), 1.0, 100.0)
    if m <= 1.0:
        raise _fail(source, "weights.e_peak", get("e_peak"), "in (1, 100] (|S| peaks above 1)")
    a = _check_range(source, "weights.e_dc", get("e_dc"), 0.0, 1.0)
    if a >= 1.0:
        raise _fail(source, "weights.e_dc", get("e_dc"), "in [0, 1) (|S(0)| below 1)")
    wu = _check_pos(source, "weights.u_crossover_rad_s", get("u_crossover_rad_s"), 100.0)
    mu = _check_pos(source, "weights.u_dc", get("u_dc"), 1e4)
    eu = _check_range(source, "weights.u_hf", get("u_hf"), 0.0, 1e4)
    if eu >= mu:
        raise _fail(
            source, "weights.u_hf", get("u_hf"), f"in [0, u_dc = {mu:g}) (W_u is a high-pass)"
        )
    if mode == "integral":
        return None
    return PerformanceShaping(wb, m, a, wu, mu, eu)


def load_config(path: str | Path | None = None) -> DesignConfig:
    """Load and validate a design TOML file (the shipped default when ``path`` is None).

    Raises
    ------
    ConfigError
        If the file cannot be read or parsed, or any field is invalid.
    """
    p = default_config_path() if path is None else Path(path)
    try:
        with open(p, "rb") as fh:
            table = tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{p}: file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: not valid TOML ({exc})") from None
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read ({exc.strerror})") from None
    return parse_config(table, source=str(p))
