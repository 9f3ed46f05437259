"""``pressor verify [ARTIFACT | --controller SPEC] [--json FILE] [--density N] [--p-dependence ...]``.

Runs :func:`pressor.synthesis.verification.verify.verify_artifact` on ARTIFACT (default: the shipped
``synthesis/data/default_design.npz``), prints progress on stderr (one line per stage and per
solver iteration: iteration, cost, relative gap, residuals) and a summary on stdout, and
optionally writes the full report as JSON (``nominal_step.lpv`` / ``.pi`` / ``.smith`` carry the
metric names of docs/METRICS.md; ``smith`` is the scheduled Smith predictor, lambda 30 s;
``artifact.controller`` the artifact's family, :mod:`pressor.synthesis.families.registry`). Exit codes:
0 every check passed, 1 a check failed, 2 bad input (a missing, unreadable or corrupt artifact, a
bad option value) with one line naming it.

``--controller SPEC`` checks a plugin controller instead of an artifact
(:mod:`pressor.synthesis.verification.plugin`): its nominal step beside the PI and the Smith predictor, and
the line ``certificate: not applicable (plugin controller)...``; exit 0 when the step is stable and
settles, 1 when it does not (or the plugin raised, or returned a non-finite command), 2 when the
spec names no loadable plugin. ``synthesis`` does not import the runtime's loader: the ``pressor``
front door (:mod:`pressor.verify`) passes it in as ``load_plugin``.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from pressor.plumbing.usage import UsageError, UsageParser, run_command
from pressor.synthesis.artifact_path import default_artifact_path
from pressor.synthesis.solver.kkt import DEFAULT_KKT_CHAIN, KKT_METHODS, kkt_chain, parse_kkt_chain

DEFAULT_ARTIFACT = default_artifact_path()
#: the loop period (s) a plugin is loaded at: the runtime's default 10 Hz
PLUGIN_PERIOD_S = 0.1


def _parser(command: str) -> UsageParser:
    p = UsageParser(
        prog=f"pressor {command}",
        description="Independent checks of a controller artifact on a grid denser than the "
        "synthesis grid: analysis LMI, frozen delay-system stability, nominal step vs PI and "
        "Smith predictor.",
    )
    p.add_argument(
        "artifact",
        nargs="?",
        default=None,
        help=f"artifact .npz (default: the shipped design, {DEFAULT_ARTIFACT.name})",
    )
    p.add_argument(
        "--controller",
        metavar="SPEC",
        help="check a plugin controller (MODULE:CLASS[:ARGS], FILE.py:CLASS[:ARGS], an entry"
        " point NAME[:ARGS]) instead of an artifact: its nominal step only, no certificate"
        " (default: none, the artifact's checks)",
    )
    p.add_argument(
        "--json", metavar="FILE", help="write the full report as JSON to FILE (default: none)"
    )
    p.add_argument(
        "--density",
        type=int,
        default=2,
        help="subdivisions of each synthesis-grid cell per axis (count, >= 2)",
    )
    p.add_argument(
        "--p-dependence",
        choices=("quadratic", "affine", "constant"),
        default="quadratic",
        help="Lyapunov matrix of the analysis LMI (default quadratic in rho, the synthesis basis)",
    )
    p.add_argument(
        "--kkt",
        default=",".join(a.method for a in DEFAULT_KKT_CHAIN),
        metavar="CHAIN",
        help="Clarabel KKT solvers tried in order while a solve ends in a numerical failure, "
        f"from {', '.join(KKT_METHODS)} (default: %(default)s; one name forces it)",
    )
    return p


def _fmt(value: object, unit: str = "") -> str:
    if value is None:
        return "n/a"
    if isinstance(value, float):
        return f"{value:.4g}{unit}"
    return f"{value}{unit}"


#: resolves a plugin spec at a loop period (s) to a controller; raises ValueError naming the spec
PluginLoader = Callable[[str, float], Any]


def main(command: str, argv: list[str], load_plugin: PluginLoader | None = None) -> int:
    """Entry point (the ``pressor`` front door, :mod:`pressor.verify`, gives ``load_plugin``);
    returns the exit code."""
    return run_command(f"pressor {command}", lambda args: _verify(command, args, load_plugin), argv)


def _verify(command: str, argv: Sequence[str], load_plugin: PluginLoader | None) -> int:
    args = _parser(command).parse_args(argv)
    if args.controller is not None:
        return _verify_plugin(args, load_plugin)
    if args.artifact is None:
        args.artifact = str(DEFAULT_ARTIFACT)
    if args.density < 2 or args.density > 16:
        raise UsageError(f"--density {args.density} outside the allowed range 2..16")
    try:
        chain = parse_kkt_chain(args.kkt)
    except ValueError as exc:
        raise UsageError(f"--kkt: {exc}") from None
    path = Path(args.artifact)
    if not path.is_file():
        raise UsageError(f"artifact {path}: file not found")
    _check_json_dir(args.json)

    from pressor.synthesis.artifact import ArtifactError, load_artifact
    from pressor.synthesis.verification.verify import verify_artifact

    try:
        artifact = load_artifact(path)
    except ArtifactError as exc:
        raise UsageError(str(exc)) from None
    except (OSError, ValueError) as exc:
        raise UsageError(f"artifact {path}: unreadable ({exc})") from None

    t0 = time.perf_counter()

    def progress(msg: str) -> None:
        print(f"[{time.perf_counter() - t0:7.1f} s] {msg}", file=sys.stderr, flush=True)

    print(f"verifying {path} (sha256 {str(getattr(artifact, 'sha256', ''))[:16]}...)", flush=True)
    with kkt_chain(chain):
        report = verify_artifact(
            artifact, density=args.density, progress=progress, p_dependence=args.p_dependence
        )
    d = report.to_dict()
    d["artifact"]["controller"] = artifact.family.to_dict()
    lmi, stab, step, claim = (
        d["analysis_lmi"],
        d["delay_stability"],
        d["nominal_step"],
        d["paper_claim"],
    )
    ok = {True: "PASS", False: "FAIL"}
    print(
        f"(a) analysis LMI      {ok[lmi['certified']]}  gamma {_fmt(lmi['gamma'])} "
        f"(synthesis {_fmt(lmi['synthesis_gamma'])}), {lmi['n_lmis']} LMIs, "
        f"status {lmi['status']}, failed points {lmi['n_failed_points']}, "
        f"min margin {_fmt(lmi['min_margin'])}, P {lmi['p_dependence']}"
    )
    print(
        f"(b) delay stability   {ok[stab['stable']]}  max Re(s) "
        f"{_fmt(stab['max_real_part_per_s'], ' 1/s')} at rho {stab['worst_rho']}"
    )
    print(f"(c) nominal step LPV structure: {step['lpv']['structure']}")
    for name in ("lpv", "pi", "smith"):
        m = step[name]
        print(
            f"(c) nominal step {name.upper():5s}  overshoot {_fmt(m['overshoot_pct'], ' %')}, "
            f"rise {_fmt(m['rise_time_s'], ' s')}, settling {_fmt(m['settling_time_s'], ' s')}, "
            f"max rate {_fmt(m['max_rate_ml_h'], ' ml/h')}"
        )
    print(
        f"paper claim (LPV overshoot < 1 %, settling < 200 s): "
        f"{'holds' if claim['holds'] else 'does not hold'}"
    )
    print(
        "LPV settles before the Smith baseline: "
        f"{'yes' if claim.get('settles_before_smith') else 'no'}"
    )
    print(f"verification {ok[report.passed]}")
    _write_json(args.json, d)
    return 0 if report.passed else 1


def _verify_plugin(args: Any, load_plugin: PluginLoader | None) -> int:
    """``--controller SPEC``: the plugin's nominal step (:mod:`pressor.synthesis.verification.plugin`)."""
    if args.artifact is not None:
        raise UsageError(
            f"--controller {args.controller!r} and artifact {args.artifact}: give one (a plugin"
            " has no artifact)"
        )
    certificate_options = [
        flag
        for flag, given, default in (
            ("--density", args.density, 2),
            ("--p-dependence", args.p_dependence, "quadratic"),
            ("--kkt", args.kkt, ",".join(a.method for a in DEFAULT_KKT_CHAIN)),
        )
        if given != default
    ]
    if certificate_options:
        raise UsageError(
            f"{', '.join(certificate_options)} with --controller: these options apply to an"
            " artifact's certificate, and a plugin controller has none"
        )
    if load_plugin is None:
        raise UsageError("--controller needs the runtime's plugin loader: run it as pressor verify")
    _check_json_dir(args.json)
    from pressor.synthesis.verification.plugin import verify_plugin_step
    from pressor.synthesis.verification.step_response import NOMINAL_STEP_MMHG

    try:
        controller = load_plugin(args.controller, PLUGIN_PERIOD_S)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    d = verify_plugin_step(controller, args.controller)
    ctl, step = d["controller"], d["nominal_step"]
    print(
        f"verifying plugin controller {ctl['spec']} (class {ctl['class']}, Ts"
        f" {ctl['sample_period_s']:g} s, max rate {ctl['max_rate_ml_h']:g} ml/h)",
        flush=True,
    )
    print(f"certificate: {d['certificate']['text']}")
    rho = step["rho"]
    print(
        f"(c) nominal step: +{NOMINAL_STEP_MMHG:g} mmHg from {step['baseline_mmhg']:g} mmHg,"
        f" K {rho[0]:g}, T {rho[1]:g} s, tau {rho[2]:g} s, horizon {step['horizon_s']:g} s"
    )
    for name in ("plugin", "pi", "smith"):
        m = step[name]
        if "error" in m:
            print(f"(c) nominal step {name.upper():6s} FAIL: {m['error']}")
            continue
        clamped = f", clamped {m['commands_clamped']} ticks" if name == "plugin" else ""
        print(
            f"(c) nominal step {name.upper():6s} overshoot {_fmt(m['overshoot_pct'], ' %')}, "
            f"rise {_fmt(m['rise_time_s'], ' s')}, settling {_fmt(m['settling_time_s'], ' s')}, "
            f"max rate {_fmt(m['max_rate_ml_h'], ' ml/h')}{clamped}"
        )
    ok = {True: "PASS", False: "FAIL"}
    print(f"verification {ok[d['passed']]} (nominal step only; no certificate)")
    _write_json(args.json, d)
    return 0 if d["passed"] else 1


def _check_json_dir(path: str | None) -> None:
    if path:
        out_dir = Path(path).resolve().parent
        if not out_dir.is_dir():
            raise UsageError(f"--json {path}: directory {out_dir} does not exist")


def _write_json(path: str | None, d: dict[str, Any]) -> None:
    if path:
        try:
            Path(path).write_text(json.dumps(d, indent=2) + "\n")
        except OSError as exc:
            raise UsageError(f"--json {path}: cannot write ({exc})") from None
