"""The design TOML's [controller] and [weights] sections (:mod:`pressor.synthesis.problem.config_toml`
reads the rest): the controller family and its loop gain, and the frequency-shaping weights."""

from __future__ import annotations

from typing import Any

from pressor.synthesis.families.registry import (
    DEFAULT_STRUCTURE,
    LOOP_GAIN_RANGE,
    ControllerFamily,
    family_named,
    structures,
)
from pressor.synthesis.problem.config import PerformanceShaping, field_check, field_error

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


def parse_controller(table: dict[str, Any], source: str) -> ControllerFamily:
    """The [controller] section, read from ``table`` only (absent: the default family, see
    module doc)."""
    sec = table.get("controller", {})
    structure = sec.get("structure", DEFAULT_STRUCTURE)
    names = structures()
    if structure not in names:
        allowed = ", ".join(repr(n) for n in names)
        raise field_error(source, "controller.structure", structure, f"one of {allowed}")
    lo, hi = LOOP_GAIN_RANGE
    if not family_named(structure).takes_loop_gain:
        if "loop_gain" in sec:
            raise field_error(
                source,
                "controller.loop_gain",
                sec["loop_gain"],
                f"absent for structure {structure!r}",
            )
        return ControllerFamily(structure)
    if "loop_gain" not in sec:
        raise field_error(
            source, "controller.loop_gain", None, f"given for {structure!r}, in ({lo:g}, {hi:g}]"
        )
    check = field_check(source)
    return ControllerFamily(
        structure, check("controller.loop_gain", sec["loop_gain"], 0.0, hi, lo_open=True)
    )


def parse_shaping(table: dict[str, Any], source: str) -> PerformanceShaping | None:
    """The [weights] frequency-shaping keys (validated even when ``performance = "integral"``)."""
    sec = table.get("weights", {})

    def get(key: str) -> Any:
        return sec.get(key, SHAPING_DEFAULTS[key])

    mode = get("performance")
    if mode not in ("integral", "shaped"):
        raise field_error(source, "weights.performance", mode, "one of 'integral', 'shaped'")
    check = field_check(source)
    wb = check("weights.e_crossover_rad_s", get("e_crossover_rad_s"), 0.0, 10.0, lo_open=True)
    m = check("weights.e_peak", get("e_peak"), 1.0, 100.0)
    if m <= 1.0:
        raise field_error(
            source, "weights.e_peak", get("e_peak"), "in (1, 100] (|S| peaks above 1)"
        )
    a = check("weights.e_dc", get("e_dc"), 0.0, 1.0)
    if a >= 1.0:
        raise field_error(source, "weights.e_dc", get("e_dc"), "in [0, 1) (|S(0)| below 1)")
    wu = check("weights.u_crossover_rad_s", get("u_crossover_rad_s"), 0.0, 100.0, lo_open=True)
    mu = check("weights.u_dc", get("u_dc"), 0.0, 1e4, lo_open=True)
    eu = check("weights.u_hf", get("u_hf"), 0.0, 1e4)
    if eu >= mu:
        raise field_error(
            source, "weights.u_hf", get("u_hf"), f"in [0, u_dc = {mu:g}) (W_u is a high-pass)"
        )
    if mode == "integral":
        return None
    return PerformanceShaping(wb, m, a, wu, mu, eu)
