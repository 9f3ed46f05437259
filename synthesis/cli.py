"""``pressor synth``: synthesize, verify and write one controller artifact.

::

    pressor synth [--config FILE.toml] [--grid a,b,c] [--out PATH] [--lambda-search]
                  [--lambda2 L2] [--lambda3 L3] [--backoff B] [--no-verify] [--quiet]

Prints progress on stderr (per λ point, per stage and one line per solver iteration: iteration,
cost, relative gap, primal and dual residuals), then on stdout γ, solve time, solver status and the
verification verdict (from :func:`synthesis.verify.verify_artifact`; the result is stored in the artifact's
``verification`` field). Exit codes: 0 ok, 1 the synthesis finished but the solver or the
verification failed, 2 bad usage or a bad config value (one line naming file, field, value and
allowed range).

A design whose ``[controller] structure = "smith"`` (:mod:`synthesis.family`) has no synthesis LMI:
the design stage is the Wirtinger analysis of its closed-form law on the design grid
(:func:`synthesis.smith_design.design_smith`, progress on stderr); if it does not certify, the
command says so, writes nothing and exits 1. ``--lambda-search``, ``--lambda2``, ``--lambda3`` and
``--backoff`` are Theorem-3 options and a usage error (exit 2) for that family.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from contracts.usage import UsageError, UsageParser, run_command
from synthesis.kkt import DEFAULT_KKT_CHAIN, KKT_METHODS, kkt_chain, parse_kkt_chain

if TYPE_CHECKING:
    from synthesis.artifact import ControllerArtifact

DEFAULT_OUT = "design.npz"


def _parser() -> UsageParser:
    p = UsageParser(
        prog="pressor synth",
        description="Design stage: certify the config's controller family (the shipped smith "
        "family: a Wirtinger analysis LMI of its closed-form law; theorem3: the paper's synthesis "
        "LMIs), verify it and write the artifact (cvxpy + Clarabel).",
    )
    p.add_argument("--config", help="design TOML (default: the shipped default design)")
    p.add_argument(
        "--grid",
        help="synthesis grid nK,nT,ntau, nodes per axis (each 2..15; default: the config's)",
    )
    p.add_argument("--out", default=DEFAULT_OUT, help="artifact path (.npz)")
    p.add_argument(
        "--lambda-search", action="store_true", help="line search over (lambda2, lambda3)"
    )
    p.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="local worker processes for --lambda-search, 1..64 (each solve ~0.4 GB)",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run the --lambda-search solves on a Dask cluster, e.g. tcp://127.0.0.1:8786 "
        "(default: local, see --jobs); same result",
    )
    p.add_argument(
        "--lambda2", type=float, help="fixed lambda2, dimensionless (default: the config's)"
    )
    p.add_argument(
        "--lambda3", type=float, help="fixed lambda3, dimensionless (default: the config's)"
    )
    p.add_argument(
        "--backoff",
        type=float,
        help="accept gamma up to (1+B) gamma*, B dimensionless in [0, 1] (default: the config's)",
    )
    p.add_argument(
        "--kkt",
        default=",".join(a.method for a in DEFAULT_KKT_CHAIN),
        metavar="CHAIN",
        help="Clarabel KKT solvers tried in order while a solve ends in a numerical failure, "
        f"from {', '.join(KKT_METHODS)} (default: %(default)s; one name forces it; "
        "in-process solves only, not the --lambda-search workers)",
    )
    p.add_argument("--no-verify", action="store_true", help="skip the independent verification")
    p.add_argument("--quiet", action="store_true", help="no progress lines (stderr)")
    return p


def _parse_grid(text: str) -> tuple[int, int, int] | None:
    parts = text.split(",")
    if len(parts) != 3:
        return None
    try:
        vals = tuple(int(v) for v in parts)
    except ValueError:
        return None
    if not all(2 <= v <= 15 for v in vals):
        return None
    return vals  # type: ignore[return-value]


#: wall-clock entries of a verification report; left out of the artifact so that the same
#: command reproduces the same bytes (they are printed by the verification progress instead)
_WALL_KEYS = frozenset({"solve_time_s", "build_time_s", "wall_time_s", "elapsed_s"})


def _without_wall_times(obj):
    if isinstance(obj, dict):
        return {k: _without_wall_times(v) for k, v in obj.items() if k not in _WALL_KEYS}
    if isinstance(obj, list):
        return [_without_wall_times(v) for v in obj]
    return obj


def main(command: str, argv: list[str]) -> int:
    """Entry point for ``pressor synth`` (see module docstring for exit codes)."""
    return run_command(f"pressor {command}", _synth, argv)


def _synth(argv: Sequence[str]) -> int:
    from synthesis.blas_threads import single_blas_thread

    single_blas_thread()  # before numpy is imported (see synthesis.blas_threads)
    args = _parser().parse_args(argv)
    if not 1 <= args.jobs <= 64:
        raise UsageError(f"field '--jobs' = {args.jobs} outside [1, 64]")
    try:
        chain = parse_kkt_chain(args.kkt)
    except ValueError as exc:
        raise UsageError(f"--kkt: {exc}") from None
    with kkt_chain(chain):
        return _synth_with(args)


def _synth_with(args: argparse.Namespace) -> int:

    from dataclasses import replace

    from synthesis.config import ConfigError
    from synthesis.config_toml import load_config
    from synthesis.synthesize import SynthesisError, synthesize

    def say(msg: str) -> None:
        if not args.quiet:
            print(f"[synth {time.perf_counter() - t0:6.1f} s] {msg}", file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    try:
        cfg = load_config(args.config)
        if args.grid is not None:
            g = _parse_grid(args.grid)
            if g is None:
                raise UsageError(
                    f"--grid: field 'grid' = {args.grid!r}: must be three integers "
                    "nK,nT,ntau each in [2, 15]"
                )
            cfg = cfg.with_grid(g)
        if args.lambda2 is not None or args.lambda3 is not None:
            cfg = cfg.with_lambdas(
                cfg.solver.lambda2 if args.lambda2 is None else args.lambda2,
                cfg.solver.lambda3 if args.lambda3 is None else args.lambda3,
            )
        if args.backoff is not None:
            if not 0.0 <= args.backoff <= 1.0:
                raise UsageError(
                    f"--backoff: field 'solver.backoff' = {args.backoff!r}: must be in [0, 1]"
                )
            cfg = replace(cfg, solver=replace(cfg.solver, backoff=args.backoff))
    except ConfigError as exc:
        raise UsageError(str(exc)) from None

    out = Path(args.out)
    say(f"config {cfg.source}; grid {cfg.grid_points}; box {cfg.model.box.tolist()}")
    if cfg.controller.is_smith:
        theorem3_only = {
            "--lambda-search": args.lambda_search,
            "--lambda2": args.lambda2 is not None,
            "--lambda3": args.lambda3 is not None,
            "--backoff": args.backoff is not None,
        }
        for option, given in theorem3_only.items():
            if given:
                raise UsageError(f"{option}: a Theorem-3 option, unused by structure 'smith'")
        from synthesis.smith_design import SmithDesignError, design_smith

        try:
            art = design_smith(cfg, progress=say)
        except SmithDesignError as exc:
            print(f"pressor synth: not certified: {exc}", file=sys.stderr)
            return 1
        for note in art.metadata["solver"]["notes"]:
            if note.startswith("KKT fallback"):  # said even with --quiet: the result depends on it
                print(f"pressor synth: {note}", file=sys.stderr)
        print(f"controller       smith, loop gain {cfg.controller.loop_gain:g}")
        print(f"gamma            {art.gamma:.6g} (Wirtinger analysis, design grid)")
        print(f"solver status    {art.metadata['solver']['status']}")
        return _verify_and_save(art, out, args.no_verify, say, t0)
    extra: dict = {}
    if args.lambda_search:
        from contracts.parallel import BackendError
        from synthesis.line_search import search

        try:
            best, pts = search(cfg, progress=say, jobs=args.jobs, scheduler=args.scheduler)
        except BackendError as exc:
            raise UsageError(str(exc)) from None
        extra["line_search"] = [
            {"lambda2": p.lambda2, "lambda3": p.lambda3, "status": p.status, "gamma": p.gamma}
            for p in pts
        ]
        if best is None:
            print(
                "pressor synth: no (lambda2, lambda3) candidate reached 'optimal'", file=sys.stderr
            )
            return 1
        say(f"lambda search: best lambda2={best[0]:g}, lambda3={best[1]:g}")
        cfg = cfg.with_lambdas(*best)
    try:
        res = synthesize(cfg, progress=say, extra_meta=extra or None)
    except SynthesisError as exc:
        print(f"pressor synth: synthesis failed: {exc}", file=sys.stderr)
        return 1
    art = res.artifact
    assert art is not None
    print(f"gamma            {res.result.gamma:.6g}")
    print(f"solver status    {res.result.status} ({res.result.iterations} iterations)")
    print(f"build / solve    {res.result.build_time_s:.2f} s / {res.result.solve_time_s:.1f} s")
    return _verify_and_save(art, out, args.no_verify, say, t0)


def _verify_and_save(
    art: ControllerArtifact, out: Path, no_verify: bool, say: Callable[[str], None], t0: float
) -> int:
    """Verify (unless ``no_verify``), store the verdict in the artifact, write it; the exit code."""
    from synthesis.artifact import save_artifact, with_verification

    verdict_code = 0
    if no_verify:
        print("verification     skipped (--no-verify)")
    else:
        from synthesis.verify import verify_artifact

        say("verify: independent checks ...")
        report = verify_artifact(art, density=2, progress=say)
        art = with_verification(art, _without_wall_times(report.to_dict()))
        print(f"verification     {'PASSED' if report.passed else 'FAILED'}")
        verdict_code = 0 if report.passed else 1
    try:
        save_artifact(art, out)
    except OSError as exc:
        raise UsageError(
            f"--out: field 'out' = {str(out)!r}: cannot write ({exc.strerror})"
        ) from None
    print(f"artifact         {out} (sha256 {art.sha256})")
    print(f"wall time        {time.perf_counter() - t0:.1f} s")
    return verdict_code
