"""Controllers as plugins: ``--controller MODULE:CLASS[:ARGS]``, ``FILE.py:CLASS[:ARGS]``, ``NAME[:ARGS]``.

Any class whose instances satisfy :class:`pressor.contracts.controller.Controller` runs wherever the shipped
controllers run (``pressor sil``, ``pressor run``, ``pressor trial``, :mod:`pressor.api`), behind
the same supervisor, clamps and rate limits: the runtime's core (:mod:`pressor.runtime.core.closed_loop`)
steps it and the supervisor turns what it returns into the pump command (non-finite:
``COMMAND_INVALID``, HOLD; outside [0, ``max_rate_ml_h``]: clamped, ``COMMAND_CLAMPED``, alarm). A
controller that raises ends ``pressor sil`` and ``trial`` with
:class:`pressor.runtime.core.closed_loop.ControllerError` naming it; under ``pressor run`` the supervisor
holds the last command until the clinician acknowledges (``CONTROLLER_FAULT``,
:mod:`pressor.runtime.core.supervisor`). The whole contract: docs/INTERFACES.md, "Controller".

Spec forms (the first that applies):

``NAME[:ARGS]``
    An entry point ``NAME`` of the group :data:`ENTRY_POINT_GROUP` (``pressor.controllers``) of an
    installed package, whose value is ``module:Class``.
``MODULE:CLASS[:ARGS]``
    ``CLASS`` of the importable module ``MODULE`` (dotted; on ``sys.path``/``PYTHONPATH``).
``FILE.py:CLASS[:ARGS]``
    ``CLASS`` of the Python file ``FILE.py``, imported from its path (no integrity check: that is
    for modules ``pressor codegen`` generates, named by a bare ``FILE.py``).

``ARGS`` are comma-separated constructor arguments, ``key=value`` (keyword) or ``value``
(positional), each value a Python literal (``2.5``, ``True``, ``'x'``) or else a string:
``pkg.ctrl:Gain:kp=0.8,ki=0.01``. The class is called with those arguments and, when its
constructor takes it (or ``**kwargs``) and ``ARGS`` do not give it, ``sample_period_s=`` the loop
period (s). The instance is then checked: callable ``step`` taking
``(map_mmhg, target_mmhg, K, T, tau)`` and ``reset``; numeric ``sample_period_s`` equal to the loop
period (s) and ``max_rate_ml_h`` in (0, 10000] ml/h; a ``status`` with ``saturated``,
``rho_clamped`` and ``rho_rate_limited``. A spec is resolved again from its text in every worker
process, so the module must be importable there too (a file path always is).
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib
import importlib.util
import inspect
import math
import re
import sys
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

from pressor.contracts.controller import Controller
from pressor.runtime.inputs.controller_loader import ControllerSpecError

#: the entry point group installed packages register controllers under (name = "module:Class")
ENTRY_POINT_GROUP = "pressor.controllers"
#: largest pump limit (ml/h) a controller may declare (the supervisor's own bound)
MAX_RATE_LIMIT_ML_H = 10000.0
#: the flags a controller's ``status`` carries (pressor.contracts.controller.ControllerStatus)
STATUS_FLAGS = ("saturated", "rho_clamped", "rho_rate_limited")

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.-]*$")
_MODULE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")


class ControllerPluginError(ControllerSpecError):
    """A plugin controller spec that cannot be used (names the spec, module, class and reason)."""


def is_plugin_spec(spec: str) -> bool:
    """Whether ``spec`` has a plugin's form (``X:Y...``, or an installed entry point's name)."""
    head = spec.partition(":")[0]
    return head in _entry_points() or (":" in spec and head not in ("", "smith"))


@functools.cache
def _entry_points() -> dict[str, str]:
    """name -> ``module:Class`` of every installed :data:`ENTRY_POINT_GROUP` entry point."""
    return {ep.name: ep.value for ep in entry_points(group=ENTRY_POINT_GROUP)}


def refresh_entry_points() -> None:
    """Forget the cached entry points (after installing a package in a running process)."""
    _entry_points.cache_clear()


def split_spec(spec: str) -> tuple[str, str, str]:
    """``(module or FILE.py, class, args text)`` of a plugin spec.

    Raises
    ------
    ControllerPluginError
        A spec that is neither an entry point name nor ``MODULE:CLASS[:ARGS]``.
    """
    head, _, rest = spec.partition(":")
    eps = _entry_points()
    if head in eps:
        module, _, cls = eps[head].partition(":")
        args = rest
    else:
        module, cls, args = head, *rest.partition(":")[::2]
    if module.endswith(".py"):
        ok = bool(cls)
    else:
        ok = bool(_MODULE.match(module))
    if not ok or not cls.isidentifier():
        raise ControllerPluginError(
            f"--controller {spec!r}: expected MODULE:CLASS[:ARGS], FILE.py:CLASS[:ARGS] or the"
            f" name of an installed '{ENTRY_POINT_GROUP}' entry point"
            f" ({', '.join(sorted(eps)) or 'none installed'})"
        )
    return module, cls, args


def parse_args(text: str, where: str) -> tuple[list[Any], dict[str, Any]]:
    """Positional and keyword constructor arguments of ``ARGS`` (``a,b,key=value,...``)."""
    positional: list[Any] = []
    keywords: dict[str, Any] = {}
    if not text:
        return positional, keywords
    for item in text.split(","):
        key, eq, value = item.partition("=")
        if not eq:
            if keywords:
                raise ControllerPluginError(f"{where}: positional argument {item!r} after keywords")
            positional.append(_literal(item))
        elif not key.strip().isidentifier():
            raise ControllerPluginError(f"{where}: argument {item!r}: expected key=value")
        else:
            keywords[key.strip()] = _literal(value)
    return positional, keywords


def _literal(text: str) -> Any:
    try:
        return ast.literal_eval(text.strip())
    except (ValueError, SyntaxError):
        return text.strip()


def _import_module(module: str, where: str) -> Any:
    try:
        return _import_cached(module)
    except _ImportFailed as exc:
        raise ControllerPluginError(f"{where}: {exc}") from None


class _ImportFailed(Exception):
    pass


@functools.cache
def _import_cached(module: str) -> Any:
    """The module ``module`` (dotted name, or a FILE.py imported once per process by path)."""
    if not module.endswith(".py"):
        try:
            return importlib.import_module(module)
        except Exception as exc:  # ImportError or the module's own error at import
            raise _ImportFailed(
                f"cannot import module {module!r}: {exc!r} (is it on PYTHONPATH? a file can be"
                " named by its path: FILE.py:CLASS)"
            ) from None
    path = Path(module).resolve()
    if not path.is_file():
        raise _ImportFailed(f"controller file {str(path)!r} not found")
    name = "_pressor_plugin_" + hashlib.sha256(str(path).encode()).hexdigest()[:16]
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise _ImportFailed(f"{str(path)!r} is not an importable Python file")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod  # before exec: dataclasses and pickling look their module up
    try:
        spec.loader.exec_module(mod)
    except Exception as exc:
        del sys.modules[name]
        raise _ImportFailed(f"importing {str(path)!r} failed: {exc!r}") from None
    return mod


def load_plugin_controller(spec: str, sample_period_s: float) -> Controller:
    """A fresh, checked instance of the plugin controller ``spec`` at ``sample_period_s`` (s).

    Raises
    ------
    ControllerPluginError
        Naming the spec, the module, the class and what is missing or out of range: a module
        that does not import, no such class, a constructor that fails, or an instance that does
        not satisfy :class:`pressor.contracts.controller.Controller`.
    """
    module, cls_name, args_text = split_spec(spec)
    where = f"--controller {spec!r}"
    cls = getattr(_import_module(module, where), cls_name, None)
    if not callable(cls):
        raise ControllerPluginError(f"{where}: module {module!r} has no class {cls_name!r}")
    what = f"{where}: class {cls_name!r} of module {module!r}"
    positional, keywords = parse_args(args_text, where)
    if "sample_period_s" not in keywords and _takes_period(cls, positional):
        keywords["sample_period_s"] = sample_period_s
    try:
        controller = cls(*positional, **keywords)
    except Exception as exc:  # the plugin's own error: reported, not raised through
        raise ControllerPluginError(f"{what}: constructor failed: {exc!r}") from None
    check_controller(controller, what, sample_period_s)
    return controller


def _takes_period(cls: Any, positional: list[Any]) -> bool:
    """Whether ``cls(*positional, sample_period_s=...)`` passes the period by keyword."""
    try:
        sig = inspect.signature(cls)
        bound = sig.bind_partial(*positional).arguments
    except (TypeError, ValueError):
        return False
    if "sample_period_s" in bound:  # given positionally
        return False
    return any(
        p.name == "sample_period_s" or p.kind is p.VAR_KEYWORD for p in sig.parameters.values()
    )


def check_controller(controller: Any, what: str, sample_period_s: float) -> None:
    """Check that ``controller`` satisfies :class:`pressor.contracts.controller.Controller` at the loop
    period ``sample_period_s`` (s); ``what`` starts the message.

    Raises
    ------
    ControllerPluginError
        Listing every missing member, or the value out of range and its allowed range.
    """
    missing = [
        f"method {m}()" for m in ("step", "reset") if not callable(getattr(controller, m, None))
    ]
    missing += [
        f"numeric attribute {m} ({unit})"
        for m, unit in (("sample_period_s", "s"), ("max_rate_ml_h", "ml/h"))
        if not _is_number(getattr(controller, m, None))
    ]
    try:
        status = controller.status
    except Exception:
        status = None
    if status is None or not all(hasattr(status, f) for f in STATUS_FLAGS):
        missing.append(f"status with {', '.join(STATUS_FLAGS)}")
    if missing:
        raise ControllerPluginError(
            f"{what} does not satisfy pressor.contracts.controller.Controller: missing {'; '.join(missing)}"
        )
    try:
        inspect.signature(controller.step).bind(0.0, 0.0, 0.0, 0.0, 0.0)
    except TypeError:
        raise ControllerPluginError(
            f"{what}: step() must take (map_mmhg, target_mmhg, K, T, tau) positionally"
        ) from None
    except ValueError:
        pass  # no signature to inspect (a builtin): trusted
    period = float(controller.sample_period_s)
    if abs(period - sample_period_s) > 1e-12:
        raise ControllerPluginError(
            f"{what}: sample_period_s = {period:g} s but the loop runs at {sample_period_s:g} s"
            " (accept a sample_period_s keyword argument, or run at its rate)"
        )
    rate = float(controller.max_rate_ml_h)
    if not 0.0 < rate <= MAX_RATE_LIMIT_ML_H:
        raise ControllerPluginError(
            f"{what}: max_rate_ml_h = {rate:g} ml/h outside (0, {MAX_RATE_LIMIT_ML_H:g}] ml/h"
        )


def plugin_label(spec: str) -> str:
    """A short name for a plugin spec: its class name (``pkg.ctrl:Gain:kp=1`` -> ``Gain``)."""
    try:
        return split_spec(spec)[1]
    except ControllerPluginError:
        return spec


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def split_controller_list(text: str) -> list[str]:
    """The specs of a comma-separated ``--controller`` list (``pressor trial``): a piece
    ``key=value`` without ``:`` continues the ARGS of the plugin spec before it
    (``lpv,pkg.ctrl:Gain:kp=1,ki=0.1,pi`` -> ``lpv``, ``pkg.ctrl:Gain:kp=1,ki=0.1``, ``pi``)."""
    specs: list[str] = []
    for piece in (p.strip() for p in text.split(",")):
        if specs and "=" in piece and ":" not in piece and _has_args(specs[-1]):
            specs[-1] += "," + piece
        else:
            specs.append(piece)
    return specs


def _has_args(spec: str) -> bool:
    if not is_plugin_spec(spec):
        return False
    head = spec.partition(":")[0]
    return spec.count(":") >= (1 if head in _entry_points() else 2)
