"""``pressor verify [ARTIFACT] [--json FILE] [--density N] [--p-dependence affine|constant]``.

Runs :func:`synthesis.verify.verify_artifact` on ARTIFACT (default: the shipped
``synthesis/data/default_design.npz``), prints progress on stderr (one line per stage and per
solver iteration: iteration, cost, relative gap, residuals) and a summary on stdout, and
optionally writes the full report as JSON (``nominal_step.lpv`` / ``.pi`` / ``.smith`` carry the
metric names of docs/METRICS.md; ``smith`` is the scheduled Smith predictor, lambda 30 s;
``artifact.controller`` the artifact's family, :mod:`synthesis.family`). Exit codes:
0 every check passed, 1 a check failed, 2 bad input (a missing, unreadable or corrupt artifact, a
bad option value) with one line naming it.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from contracts.usage import UsageError, UsageParser, run_command
from synthesis.kkt import DEFAULT_KKT_CHAIN, KKT_METHODS, kkt_chain, parse_kkt_chain

DEFAULT_ARTIFACT = Path(__file__).resolve().parent / "data" / "default_design.npz"


def _parser(command: str) -> UsageParser:
    p = UsageParser(
        prog=f"pressor {command}",
        description="Independent checks of a controller artifact on a grid denser than the "
        "synthesis grid: analysis LMI, frozen delay-system stability, nominal step vs PI and "
        "Smith predictor.",
    )
    p.add_argument("artifact", nargs="?", default=str(DEFAULT_ARTIFACT), help="artifact .npz")
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


def main(command: str, argv: list[str]) -> int:
    """Entry point used by the ``pressor`` dispatcher; returns the exit code."""
    return run_command(f"pressor {command}", lambda args: _verify(command, args), argv)


def _verify(command: str, argv: Sequence[str]) -> int:
    from synthesis.blas_threads import single_blas_thread

    single_blas_thread()  # before numpy is imported (see synthesis.blas_threads)
    args = _parser(command).parse_args(argv)
    if args.density < 2 or args.density > 16:
        raise UsageError(f"--density {args.density} outside the allowed range 2..16")
    try:
        chain = parse_kkt_chain(args.kkt)
    except ValueError as exc:
        raise UsageError(f"--kkt: {exc}") from None
    path = Path(args.artifact)
    if not path.is_file():
        raise UsageError(f"artifact {path}: file not found")
    if args.json:
        out_dir = Path(args.json).resolve().parent
        if not out_dir.is_dir():
            raise UsageError(f"--json {args.json}: directory {out_dir} does not exist")

    from synthesis.artifact import ArtifactError, load_artifact
    from synthesis.verify import verify_artifact

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
    if args.json:
        try:
            Path(args.json).write_text(json.dumps(d, indent=2) + "\n")
        except OSError as exc:
            raise UsageError(f"--json {args.json}: cannot write ({exc})") from None
    return 0 if report.passed else 1
