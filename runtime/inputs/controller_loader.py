"""Resolve a ``--controller`` spec (``pi``, ``smith[:λ]``, ``lpv``, a path or a plugin) to a :class:`Controller`.

A plugin (``MODULE:CLASS[:ARGS]``, ``FILE.py:CLASS[:ARGS]``, an installed ``pressor.controllers``
entry point) is any class satisfying the protocol, loaded and checked by
:mod:`pressor.runtime.inputs.controller_plugin`; the integrity check below is for generated modules only.

``smith`` is the scheduled Smith predictor of :mod:`pressor.baselines.smith` with its default
closed-loop time constant (30 s); ``smith:45`` sets λ = 45 s (allowed range in that module).

``lpv`` is the generated module for the shipped default design, committed at
``runtime/generated/lpv_map_controller.py``; ``lpv:DRUG`` names a drug's shipped design
(:data:`LPV_DESIGNS`: ``lpv:phenylephrine`` is ``lpv``, ``lpv:norepinephrine`` the module
``runtime/generated/lpv_norepinephrine.py`` of ``synthesis/data/norepinephrine_design.npz``);
``lpv:wide-delay`` names phenylephrine's design for a schedule sent from outside the loop with
delays to 200 s (``runtime/generated/lpv_wide_delay.py`` of
``synthesis/data/wide_delay_design.npz``); ``lpv:cautious`` phenylephrine's design on a log-K scale
for the cautious start (``--schedule cautious``; ``runtime/generated/lpv_cautious.py`` of
``synthesis/data/cautious_design.npz``), ``lpv:norepinephrine-cautious`` norepinephrine's
(``runtime/generated/lpv_norepinephrine_cautious.py`` of
``synthesis/data/norepinephrine_cautious_design.npz``); a path names any module written by ``pressor codegen``
(``--target python``). Loading a generated module imports it from its file: it must be the standard
library-only module codegen writes, exposing a ``Controller`` class. A process imports the same
verified text once (every load still checks the file first) and gives each load a fresh controller.

Integrity: before anything is executed, the file's ``MODULE_SHA256`` line must equal the sha256 of
the file's text with that value blanked (codegen writes it), so an edited, truncated or appended
module is refused with :class:`ControllerSpecError` naming the file. When the path of the artifact
the module was generated from is given, its stored sha256 must equal the module's
``ARTIFACT_SHA256`` (a stale module for a replaced design is refused too).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

from pressor.baselines.pi import PIController
from pressor.baselines.smith import LAMBDA_DEFAULT_S, LAMBDA_MAX_S, LAMBDA_MIN_S, SmithController
from pressor.contracts.controller import Controller
from pressor.contracts.module_hash import ARTIFACT_SHA_LINE, MODULE_SHA_LINE, module_text_sha256

GENERATED_DIR = Path(__file__).resolve().parents[1] / "generated"
DEFAULT_LPV_MODULE = GENERATED_DIR / "lpv_map_controller.py"
#: ``lpv:NAME`` -> the committed generated module of a shipped design: a drug's (``lpv`` alone is
#: the default design, phenylephrine at 100 µg/ml; docs/DRUGS.md) or phenylephrine's wide-delay
#: design, certified to τ 200 s for a schedule the device sends (docs/SCHEDULING.md)
LPV_DESIGNS: dict[str, Path] = {
    "phenylephrine": DEFAULT_LPV_MODULE,
    "norepinephrine": GENERATED_DIR / "lpv_norepinephrine.py",
    "wide-delay": GENERATED_DIR / "lpv_wide_delay.py",
    "cautious": GENERATED_DIR / "lpv_cautious.py",
    "norepinephrine-cautious": GENERATED_DIR / "lpv_norepinephrine_cautious.py",
}
LPV_PREFIX = "lpv"
#: the baselines every comparison shows: ``--controller`` spec -> one line (pressor designs)
BASELINES: dict[str, str] = {
    "pi": "baseline: the paper's fixed PI controller (not scheduled on K, T, tau)",
    "smith[:LAMBDA_S]": "baseline: a hand-tuned scheduled Smith predictor, closed-loop time"
    f" constant LAMBDA_S s (default {LAMBDA_DEFAULT_S:g}, allowed {LAMBDA_MIN_S:g}-{LAMBDA_MAX_S:g})",
}
#: (path, text sha256) -> the module imported from that text: a cohort loads the same module once
#: per process instead of once per patient (≈ 0.1 s for the shipped module's 0.7 MB)
_LOADED: dict[tuple[str, str], ModuleType] = {}


def design_specs() -> list[str]:
    """The ``--controller`` spec of every shipped LPV design, read from :data:`LPV_DESIGNS` (a new
    entry appears here, in ``pressor designs``, in the help and the errors): ``lpv`` for the default
    module, ``lpv:NAME`` for each other one."""
    return [
        LPV_PREFIX if path == DEFAULT_LPV_MODULE else f"{LPV_PREFIX}:{name}"
        for name, path in LPV_DESIGNS.items()
    ]


def shipped_specs() -> list[str]:
    """Every shipped controller's spec: the LPV designs (:func:`design_specs`), then the baselines."""
    return [*design_specs(), *BASELINES]


def shipped_specs_text() -> str:
    """``lpv, lpv:norepinephrine, lpv:wide-delay, pi, smith[:LAMBDA_S]``: for helps and errors."""
    return ", ".join(shipped_specs())


def design_header(path: Path) -> dict[str, object]:
    """The constants a generated module states before its code (``DRUG``,
    ``DRUG_CONCENTRATION_UG_ML``, ``GRID_LO``, ``GRID_HI``, ``RATE_BOUNDS``,
    ``GENERATION_COMMAND``, ...), read from its text without importing it (a shipped module is
    0.7 MB); ``{}`` when the file cannot be read."""
    import ast
    import re

    line = re.compile(r"^([A-Z][A-Z0-9_]*) = (.+?)(?:\s+#.*)?$")
    out: dict[str, object] = {}
    try:
        with open(path, encoding="utf-8") as f:
            for i, text in enumerate(f):
                if i > 200 or text.startswith(("def ", "class ")):
                    break
                m = line.match(text.rstrip("\n"))
                if m is None:
                    continue
                try:
                    out[m.group(1)] = ast.literal_eval(m.group(2))
                except (ValueError, SyntaxError):
                    continue
    except OSError:
        return {}
    return out


class ControllerSpecError(ValueError):
    """A ``--controller`` value that names no loadable controller (message names spec and choices)."""


SMITH_PREFIX = "smith"


def _smith(spec: str, sample_period_s: float) -> SmithController:
    """``smith`` or ``smith:LAMBDA_S``; a bad λ names the value and the allowed range."""
    _, sep, text = spec.partition(":")
    if not sep:
        return SmithController(sample_period_s=sample_period_s)
    try:
        lambda_s = float(text)
    except ValueError:
        lambda_s = float("nan")
    if not LAMBDA_MIN_S <= lambda_s <= LAMBDA_MAX_S:  # also refuses nan and inf
        raise ControllerSpecError(
            f"--controller {spec!r}: closed-loop time constant lambda {text!r} s outside "
            f"[{LAMBDA_MIN_S:g}, {LAMBDA_MAX_S:g}] s (e.g. smith:45)"
        )
    return SmithController(sample_period_s=sample_period_s, lambda_s=lambda_s)


def lpv_design_module(spec: str) -> Path | None:
    """The committed module ``lpv`` or ``lpv:NAME`` names, ``None`` for any other spec.

    Raises
    ------
    ControllerSpecError
        ``lpv:NAME`` with a name that has no shipped design (naming the ones that do).
    """
    if spec == LPV_PREFIX:
        return DEFAULT_LPV_MODULE
    head, sep, name = spec.partition(":")
    if head != LPV_PREFIX or not sep:
        return None
    if name not in LPV_DESIGNS:
        raise ControllerSpecError(
            f"--controller {spec!r}: no shipped design named {name!r}; one of"
            f" {', '.join(f'lpv:{d}' for d in LPV_DESIGNS)} (pressor designs lists them)"
        )
    return LPV_DESIGNS[name]


def verify_module_file(path: Path, artifact_sha256: str | None = None) -> str:
    """Check a generated module's self-hash (and artifact sha256); return its text.

    Raises
    ------
    ControllerSpecError
        Unreadable file, missing or mismatching ``MODULE_SHA256``, or (with ``artifact_sha256``) an
        ``ARTIFACT_SHA256`` that differs from it. The caller supplies the artifact's sha256 (the
        runtime never loads the synthesis package).
    """
    try:
        text = Path(path).read_bytes().decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ControllerSpecError(f"{path}: cannot read generated controller ({exc})") from exc
    m = MODULE_SHA_LINE.search(text)
    if m is None:
        raise ControllerSpecError(
            f"{path}: field 'MODULE_SHA256' missing; not an intact pressor codegen module"
        )
    actual = module_text_sha256(text)
    if actual != m.group(1):
        raise ControllerSpecError(
            f"{path}: field 'MODULE_SHA256' = {m.group(1)[:12]}... but the file hashes to "
            f"{actual[:12]}...; the module was modified or truncated, regenerate it with "
            "pressor codegen"
        )
    if artifact_sha256 is not None:
        a = ARTIFACT_SHA_LINE.search(text)
        if a is None or a.group(1) != artifact_sha256:
            got = a.group(1)[:12] if a else "missing"
            raise ControllerSpecError(
                f"{path}: field 'ARTIFACT_SHA256' = {got}... but the expected artifact has sha256 "
                f"{artifact_sha256[:12]}...; regenerate with pressor codegen"
            )
    return text


def load_generated_module(path: Path, artifact_sha256: str | None = None) -> ModuleType:
    """Verify (:func:`verify_module_file`) and import a generated controller module from ``path``.

    Raises
    ------
    ControllerSpecError
        If the file is missing, fails the integrity check, fails to import, or has no
        ``Controller`` class.
    """
    path = Path(path).resolve()
    if not path.is_file():
        raise ControllerSpecError(f"{path}: controller module not found")
    text = verify_module_file(path, artifact_sha256)
    key = (str(path), MODULE_SHA_LINE.search(text).group(1))  # verified: the text's own hash
    if key in _LOADED:  # the same verified text: importing it again would give the same module
        return _LOADED[key]
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
    _LOADED[key] = module
    return module


#: how a research build of a law no certificate covers marks its generation command
#: (``research/uncertified_module.py``)
UNCERTIFIED_MARK = "pressor codegen UNCERTIFIED "


def load_controller(
    spec: str,
    sample_period_s: float = 0.1,
    artifact_sha256: str | None = None,
    allow_uncertified: bool = False,
) -> Controller:
    """Return a fresh controller for ``spec``.

    Parameters
    ----------
    spec
        ``"pi"`` (the paper's PI baseline), ``"smith"`` / ``"smith:LAMBDA_S"`` (the scheduled Smith
        predictor, λ in s), ``"lpv"`` / ``"lpv:NAME"`` (a shipped generated LPV module), a path
        to a generated ``.py`` module, or a plugin (:mod:`pressor.runtime.inputs.controller_plugin`:
        ``MODULE:CLASS[:ARGS]``,
        ``FILE.py:CLASS[:ARGS]`` or an installed ``pressor.controllers`` entry point name).
    sample_period_s
        Loop period (s). A generated module is discretised for one period; a mismatch is an error.
    artifact_sha256
        Optional sha256 of the artifact the module must have been generated from.
    allow_uncertified
        Accept a research build whose ``GENERATION_COMMAND`` starts with :data:`UNCERTIFIED_MARK`
        (a law on a box no certificate covers; benchmarks only). False everywhere else.

    Raises
    ------
    ControllerSpecError
        Unknown spec, missing, tampered or broken module, artifact mismatch, a sample-period
        mismatch, or an uncertified research build without ``allow_uncertified``.
    """
    if spec == "pi":
        return PIController(sample_period_s=sample_period_s)
    if spec == SMITH_PREFIX or spec.startswith(SMITH_PREFIX + ":"):
        return _smith(spec, sample_period_s)
    from pressor.runtime.inputs.controller_plugin import is_plugin_spec, load_plugin_controller

    named = lpv_design_module(spec)
    if named is None and is_plugin_spec(spec):
        return load_plugin_controller(spec, sample_period_s)
    path = named if named is not None else Path(spec)
    if named is None and path.suffix != ".py":
        raise ControllerSpecError(
            f"--controller {spec!r}: expected a shipped controller ({shipped_specs_text()};"
            " pressor designs lists them), a path to a generated .py module, or a plugin:"
            " MODULE:CLASS[:ARGS], FILE.py:CLASS[:ARGS] or an installed 'pressor.controllers'"
            " entry point (pressor.runtime.inputs.controller_plugin)"
        )
    module = load_generated_module(path, artifact_sha256)
    command = str(getattr(module, "GENERATION_COMMAND", ""))
    if command.startswith(UNCERTIFIED_MARK) and not allow_uncertified:
        raise ControllerSpecError(
            f"{path}: field 'GENERATION_COMMAND' marks an UNCERTIFIED research build (no"
            " certificate covers its box); only the benchmarks may run it"
        )
    controller = module.Controller()
    period = float(getattr(controller, "sample_period_s", float("nan")))
    if abs(period - sample_period_s) > 1e-12:
        raise ControllerSpecError(
            f"{path}: field 'sample_period_s' = {period} s but the loop runs at {sample_period_s} s;"
            " regenerate with pressor codegen for this rate"
        )
    return controller


def controller_name(spec: str) -> str:
    """A short name for ``spec`` (the link's hello, file names): ``pi``, ``lpv``, ``smith:45`` as
    given, a generated module's file stem, a plugin's class name."""
    from pressor.runtime.inputs.controller_plugin import is_plugin_spec, plugin_label

    if spec in ("pi", "lpv") or spec == SMITH_PREFIX or spec.startswith(SMITH_PREFIX + ":"):
        return spec
    if spec.startswith(LPV_PREFIX + ":") and spec.partition(":")[2] in LPV_DESIGNS:
        return spec
    return plugin_label(spec) if is_plugin_spec(spec) else Path(spec).stem
