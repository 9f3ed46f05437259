"""Resolve a ``--controller`` spec (``pi``, ``lpv`` or a path) to a :class:`Controller` instance.

``lpv`` is the generated module for the shipped default design, committed at
``runtime/generated/lpv_map_controller.py``; a path names any module written by ``pressor codegen``
(``--target python``). Loading a generated module imports it from its file: it must be the standard
library-only module codegen writes, exposing a ``Controller`` class.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

from runtime.controller import Controller
from runtime.pi_controller import PIController

DEFAULT_LPV_MODULE = Path(__file__).resolve().parent / "generated" / "lpv_map_controller.py"


class ControllerSpecError(ValueError):
    """A ``--controller`` value that names no loadable controller (message names spec and choices)."""


def load_generated_module(path: Path) -> ModuleType:
    """Import a generated controller module from ``path`` under a name unique to that file.

    Raises
    ------
    ControllerSpecError
        If the file is missing, fails to import, or has no ``Controller`` class.
    """
    path = Path(path).resolve()
    if not path.is_file():
        raise ControllerSpecError(f"{path}: controller module not found")
    name = f"_pressor_generated_{abs(hash(str(path))):x}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ControllerSpecError(f"{path}: not an importable Python module")
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as exc:  # a tampered or truncated file: report, never crash the caller
        raise ControllerSpecError(f"{path}: failed to import generated controller: {exc}") from exc
    if not hasattr(module, "Controller"):
        raise ControllerSpecError(
            f"{path}: field 'Controller' missing; not a pressor codegen module"
        )
    sys.modules[name] = module
    return module


def load_controller(spec: str, sample_period_s: float = 0.1) -> Controller:
    """Return a fresh controller for ``spec``.

    Parameters
    ----------
    spec
        ``"pi"`` (the paper's PI baseline), ``"lpv"`` (the shipped generated LPV module) or a path to
        a generated ``.py`` module.
    sample_period_s
        Loop period (s). A generated module is discretised for one period; a mismatch is an error.

    Raises
    ------
    ControllerSpecError
        Unknown spec, missing or broken module, or a sample-period mismatch.
    """
    if spec == "pi":
        return PIController(sample_period_s=sample_period_s)
    path = DEFAULT_LPV_MODULE if spec == "lpv" else Path(spec)
    if spec != "lpv" and path.suffix != ".py":
        raise ControllerSpecError(
            f"--controller {spec!r}: expected 'pi', 'lpv' or a path to a generated .py module"
        )
    module = load_generated_module(path)
    controller = module.Controller()
    period = float(getattr(controller, "sample_period_s", float("nan")))
    if abs(period - sample_period_s) > 1e-12:
        raise ControllerSpecError(
            f"{path}: field 'sample_period_s' = {period} s but the loop runs at {sample_period_s} s;"
            " regenerate with pressor codegen for this rate"
        )
    return controller
