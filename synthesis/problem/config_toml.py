"""Reading and validating a design TOML file for the LPV synthesis.

A design is described by a TOML file with the sections below (all physical units, time in s)::

    [box]        K = [lo, hi]  (mmHg/(ml/h)),  T_s = [lo, hi] (s),  tau_s = [lo, hi] (s)
    [rates]      K_per_s (mmHg/(ml/h)/s),  T_s_per_s (s/s),  tau_s_per_s (s/s, < 1); or, instead
                 of K_per_s, K_relative_per_s (1/s, in (0, 0.2]): a bound on |d(ln K)/dt|, the design
                 certified on a log-K scale (``ModelConfig.k_rate_relative``; "smith" family only),
                 and optionally K_relative_up_per_s (1/s, in (0, 0.2]): a separate bound on its rise
    [filter]     omega (1/s), lambda (1/s)            u = omega/(s + lambda) u_a
    [weights]    phi (1/(mmHg·s)) on x_e,  xi on u_a,  eta_xe (mmHg·s) x_e measurement-noise weight,
                 performance ("integral" | "shaped") and, for "shaped", the frequency weights
                 e_crossover_rad_s (ω_b), e_peak (M), e_dc (A) of W_e(s) = (s/M + ω_b)/(s + ω_b A)
                 on the tracking error and u_crossover_rad_s (ω_u), u_dc (M_u, (ml/h)/mmHg),
                 u_hf (ε_u) of W_u(s) = (s + ω_u/M_u)/(ε_u s + ω_u) on the infusion
                 (see :mod:`pressor.synthesis.problem.model`; optional keys, defaults in
                 ``SHAPING_DEFAULTS``)
    [grid]       points = [nK, nT, ntau]              synthesis grid (each >= 2)
    [solver]     lambda2, lambda3 (scaled-time slack multipliers), backoff (fraction, >= 0),
                 epsilon (strictness margin), xy_dependence ("constant" | "x" | "xy"),
                 time_scale_s (the time unit of the scaled problem), rate_terms
                 ("vertices" | "bound"), mean_gamma_weight
    [line_search] lambda2 = [...], lambda3 = [...]   candidate values for ``--lambda-search``
    [pump]       max_rate_ml_h
    [controller] structure (a family of :func:`pressor.synthesis.families.registry.structures`), loop_gain
                 (dimensionless, in (0, 10], only and required for a family that takes it): the
                 controller family of :mod:`pressor.synthesis.families.registry`. Unlike the other sections
                 it never takes the shipped default: no [controller] section (or no ``structure``)
                 means :data:`pressor.synthesis.families.registry.DEFAULT_STRUCTURE`, so a design file
                 written before the section existed keeps its meaning. For a family without a
                 synthesis LMI the [solver] (but ``time_scale_s``) and [line_search] keys are unused
                 (they are still validated if present)
    [drug]       name (lower case, 1-16 ASCII characters), concentration_ug_ml (µg/ml, in (0, 1e5]):
                 the drug and the syringe concentration whose ml/h the design's gains count
                 (:class:`pressor.contracts.drug.DrugBinding`); carried into the artifact
                 (``design.drug``) and the generated module (``DRUG``,
                 ``DRUG_CONCENTRATION_UG_ML``); ``pressor run`` refuses any other (docs/DRUGS.md)
    [population] optional: K_ug_kg_min = [lo, hi] (mmHg per µg/kg/min, each in [1e-3, 1e7]): the
                 sensitivity of the patients the design is for, in doses (the 0.1x-10x range of
                 the drug's patient models); the cautious start schedules on its top, converted to
                 ml/h of the syringe and patient at hand (docs/notes/cautious-start.md); carried
                 into the artifact (``design.population``) and the module (``POPULATION_K_UG_KG_MIN``)
    [reference]  enabled (bool), lambda_s (s, in [1, 1000]), pump_fraction (in [0.1, 1]),
                 k_min (mmHg/(ml/h), in [0.0001, box K upper]), optional lag_s (s, in [1, 2000]:
                 the model's fixed lag; absent: the scheduled T)
                 the two-degree-of-freedom prefilter of :mod:`pressor.synthesis.problem.reference` (outside
                 the certified loop: it changes the reference and adds a feedforward, not the LMIs)

Every missing key takes the shipped default (``synthesis/data/default_design.toml``). Any bad
value raises :class:`~pressor.synthesis.problem.config.ConfigError` naming the file, the field, the value
and the allowed range.
"""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from pressor.contracts.drug import MAX_CONCENTRATION_UG_ML, MAX_DRUG_CHARS, DrugBinding
from pressor.synthesis.problem.config import (
    ConfigError,
    DesignConfig,
    ModelConfig,
    SolverConfig,
    check_grid,
    field_check,
    field_error,
)
from pressor.synthesis.problem.config_sections import (
    SHAPING_DEFAULTS,
    parse_controller,
    parse_shaping,
)
from pressor.synthesis.problem.reference import (
    K_MIN_RANGE,
    LAG_RANGE_S,
    LAMBDA_RANGE_S,
    PUMP_FRACTION_RANGE,
    ReferenceConfig,
)

__all__ = [
    "SHAPING_DEFAULTS",
    "default_config_path",
    "load_config",
    "parse_config",
    "theorem3_config_path",
]

PARAM_NAMES = ("K", "T_s", "tau_s")
RATE_NAMES = ("K_per_s", "T_s_per_s", "tau_s_per_s")

#: Allowed ranges: (lo, hi) for box edges, rates, filter, weights.
_BOX_RANGE = {"K": (1e-4, 1e4), "T_s": (1.0, 2000.0), "tau_s": (0.0, 600.0)}
_RATE_RANGE = {"K_per_s": (0.0, 1.0), "T_s_per_s": (0.0, 10.0), "tau_s_per_s": (0.0, 0.999)}
#: the relative K rate's range (1/s), the alternative to ``K_per_s``
K_RELATIVE_RANGE = (0.0, 0.2)
#: keys a design may give that the shipped default TOML does not (no default: absent = off)
OPTIONAL_KEYS = {
    "rates": ("K_relative_per_s", "K_relative_up_per_s"),
    "reference": ("lag_s",),
    "population": ("K_ug_kg_min",),
}
#: the range of a population's sensitivity (mmHg per µg/kg/min)
POPULATION_K_RANGE = (1e-3, 1e7)


def default_config_path() -> Path:
    """Path of the shipped default design TOML."""
    return Path(str(resources.files("pressor.synthesis") / "data" / "default_design.toml"))


def theorem3_config_path() -> Path:
    """Path of the Theorem-3 design TOML (the paper's synthesis on the box it solves on)."""
    return default_config_path().with_name("theorem3_design.toml")


def _get(table: dict[str, Any], section: str, key: str, default: dict[str, Any]) -> Any:
    sec = table.get(section, {})
    if key in sec:
        return sec[key]
    return default.get(section, {}).get(key)


def _merge_check_keys(source: str, table: dict[str, Any], default: dict[str, Any]) -> None:
    """Unknown sections/keys are errors (a typo must not silently fall back to a default)."""
    default = {**default, "weights": {**default.get("weights", {}), **SHAPING_DEFAULTS}}
    for section, body in table.items():
        if section not in default and section not in OPTIONAL_KEYS:
            raise field_error(source, section, "<section>", f"one of {sorted(default)}")
        if not isinstance(body, dict):
            raise field_error(source, section, body, "a TOML table")
        for key in body:
            if key not in default.get(section, {}) and key not in OPTIONAL_KEYS.get(section, ()):
                allowed = sorted({*default.get(section, {}), *OPTIONAL_KEYS.get(section, ())})
                raise field_error(source, f"{section}.{key}", body[key], f"one of {allowed}")


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
    check = field_check(source)
    for i, name in enumerate(PARAM_NAMES):
        f = f"box.{name}"
        val = _get(table, "box", name, default)
        if not isinstance(val, list | tuple) or len(val) != 2:
            raise field_error(source, f, val, "a list [lower, upper]")
        lo_ok, hi_ok = _BOX_RANGE[name]
        lo = check(f, val[0], lo_ok, hi_ok)
        hi = check(f, val[1], lo_ok, hi_ok)
        if not lo < hi:
            raise field_error(source, f, val, "a list [lower, upper] with lower < upper")
        box[i] = (lo, hi)
    if box[1, 0] <= 0.0:
        raise field_error(source, "box.T_s", box[1].tolist(), "positive")

    rates = np.zeros(3)
    for i, name in enumerate(RATE_NAMES):
        lo, hi = _RATE_RANGE[name]
        rates[i] = check(f"rates.{name}", _get(table, "rates", name, default), lo, hi)
    relative = "K_relative_per_s" in table.get("rates", {})
    if relative:
        if "K_per_s" in table["rates"]:
            raise field_error(
                source, "rates.K_per_s", table["rates"]["K_per_s"], "absent with K_relative_per_s"
            )
        rel = table["rates"]["K_relative_per_s"]
        rates[0] = check("rates.K_relative_per_s", rel, *K_RELATIVE_RANGE, lo_open=True)
    up = table.get("rates", {}).get("K_relative_up_per_s")
    if up is not None:
        if not relative:
            raise field_error(
                source, "rates.K_relative_up_per_s", up, "absent without K_relative_per_s"
            )
        up = check("rates.K_relative_up_per_s", up, *K_RELATIVE_RANGE, lo_open=True)

    omega = check("filter.omega", _get(table, "filter", "omega", default), 0.0, 100.0, lo_open=True)
    lam = check("filter.lambda", _get(table, "filter", "lambda", default), 0.0, 100.0, lo_open=True)
    phi = check("weights.phi", _get(table, "weights", "phi", default), 0.0, 1e3, lo_open=True)
    xi = check("weights.xi", _get(table, "weights", "xi", default), 0.0, 1e3, lo_open=True)
    eta = check("weights.eta_xe", _get(table, "weights", "eta_xe", default), 0.0, 1e6, lo_open=True)
    shaping = parse_shaping(table, source)
    pump = check(
        "pump.max_rate_ml_h", _get(table, "pump", "max_rate_ml_h", default), 0.0, 1e4, lo_open=True
    )
    grid = check_grid(source, "grid.points", _get(table, "grid", "points", default))

    l2 = check("solver.lambda2", _get(table, "solver", "lambda2", default), 1e-4, 1e4)
    l3 = check("solver.lambda3", _get(table, "solver", "lambda3", default), 1e-4, 1e4)
    backoff = check("solver.backoff", _get(table, "solver", "backoff", default), 0.0, 1.0)
    eps = check("solver.epsilon", _get(table, "solver", "epsilon", default), 0.0, 1e-2)
    xy = _get(table, "solver", "xy_dependence", default)
    if xy not in ("constant", "x", "xy"):
        raise field_error(source, "solver.xy_dependence", xy, "one of 'constant', 'x', 'xy'")
    ts = check(
        "solver.time_scale_s",
        _get(table, "solver", "time_scale_s", default),
        0.0,
        1e4,
        lo_open=True,
    )
    mgw = check(
        "solver.mean_gamma_weight", _get(table, "solver", "mean_gamma_weight", default), 0.0, 1e3
    )
    rt = _get(table, "solver", "rate_terms", default)
    if rt not in ("vertices", "bound"):
        raise field_error(source, "solver.rate_terms", rt, "one of 'vertices', 'bound'")

    cands = []
    for key in ("lambda2", "lambda3"):
        f = f"line_search.{key}"
        val = _get(table, "line_search", key, default)
        if not isinstance(val, list | tuple) or not 1 <= len(val) <= 20:
            raise field_error(source, f, val, "a list of 1 to 20 numbers in [1e-4, 1e4]")
        cands.append(tuple(check(f, v, 1e-4, 1e4) for v in val))

    enabled = _get(table, "reference", "enabled", default)
    if not isinstance(enabled, bool):
        raise field_error(source, "reference.enabled", enabled, "true or false")
    reference = ReferenceConfig(
        enabled=enabled,
        lambda_s=check(
            "reference.lambda_s", _get(table, "reference", "lambda_s", default), *LAMBDA_RANGE_S
        ),
        pump_fraction=check(
            "reference.pump_fraction",
            _get(table, "reference", "pump_fraction", default),
            *PUMP_FRACTION_RANGE,
        ),
        k_min=check(
            "reference.k_min",
            _get(table, "reference", "k_min", default),
            K_MIN_RANGE[0],
            min(K_MIN_RANGE[1], float(box[0, 1])),
        ),
        lag_s=None
        if (lag := table.get("reference", {}).get("lag_s")) is None
        else check("reference.lag_s", lag, *LAG_RANGE_S),
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
        k_rate_relative=relative,
        k_rate_up_per_s=up,
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
    controller = parse_controller(table, source)
    if relative and (controller.structure != "smith" or shaping is not None):
        raise field_error(
            source,
            "rates.K_relative_per_s",
            rates[0],
            "used with [controller] structure 'smith' and weights.performance 'integral'",
        )
    population = None
    if "population" in table:
        val = table["population"].get("K_ug_kg_min")
        if not isinstance(val, list | tuple) or len(val) != 2:
            raise field_error(source, "population.K_ug_kg_min", val, "a list [lower, upper]")
        lo, hi = (check("population.K_ug_kg_min", v, *POPULATION_K_RANGE) for v in val)
        if not lo < hi:
            raise field_error(source, "population.K_ug_kg_min", val, "a list with lower < upper")
        population = (lo, hi)
    return DesignConfig(
        model=model,
        grid_points=grid,
        solver=solver,
        reference=reference,
        controller=controller,
        lambda2_candidates=cands[0],
        lambda3_candidates=cands[1],
        drug=_parse_drug(table, source, default),
        population=population,
        source=source,
        raw=table,
    )


def _parse_drug(table: dict[str, Any], source: str, default: dict[str, Any]) -> DrugBinding:
    """The [drug] section (missing keys: the shipped default's)."""
    name = _get(table, "drug", "name", default)
    if not (
        isinstance(name, str)
        and name
        and name.isascii()
        and name == name.strip().lower()
        and len(name) <= MAX_DRUG_CHARS
    ):
        raise field_error(
            source, "drug.name", name, f"1 to {MAX_DRUG_CHARS} lower-case ASCII characters"
        )
    check = field_check(source)
    conc = check(
        "drug.concentration_ug_ml",
        _get(table, "drug", "concentration_ug_ml", default),
        0.0,
        MAX_CONCENTRATION_UG_ML,
        lo_open=True,
    )
    return DrugBinding(name, conc)


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
