"""``pressor synth``: synthesize, verify and write one controller artifact.

::

    pressor synth [--config FILE.toml] [--grid a,b,c] [--out PATH] [--lambda-search]
                  [--lambda2 L2] [--lambda3 L3] [--backoff B] [--no-verify] [--quiet]

Prints progress on stderr (per λ point, per stage and one line per solver iteration: iteration,
cost, relative gap, primal and dual residuals), then on stdout γ, solve time, solver status and the
verification verdict (from :func:`pressor.synthesis.verification.verify.verify_artifact`; the result is
stored in the artifact's ``verification`` field). Exit codes: 0 ok, 1 the synthesis finished but the
solver or the verification failed, 2 bad usage or a bad config value (one line naming file, field,
value and allowed range).

The design stage is the config's controller family's
(:meth:`pressor.synthesis.families.registry.Family.design`): the shipped family certifies its closed-form
law with the Wirtinger analysis on the design grid, the Theorem-3 family synthesises; if the design
does not certify, the command says so, writes nothing and exits 1. ``--lambda-search``,
``--lambda2``, ``--lambda3`` and ``--backoff`` are options of the families that list them
(:attr:`pressor.synthesis.families.registry.Family.synth_options`) and a usage error (exit 2) for the
others.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from pressor.contracts.checks import check_range
from pressor.plumbing.usage import UsageError, UsageParser, run_command
from pressor.synthesis.families.registry import SynthRequest, family_named, structures
from pressor.synthesis.solver.kkt import DEFAULT_KKT_CHAIN, KKT_METHODS, kkt_chain, parse_kkt_chain

if TYPE_CHECKING:
    from pressor.synthesis.artifact import ControllerArtifact

DEFAULT_OUT = "design.npz"


def _parser() -> UsageParser:
    p = UsageParser(
        prog="pressor synth",
        description="Design stage: certify the config's controller family (one of "
        f"{', '.join(structures())}; the shipped design's: a Wirtinger analysis LMI of its "
        "closed-form Smith law; the alternative: the paper's Theorem-3 synthesis LMIs), verify it "
        "and write the artifact (cvxpy + Clarabel).",
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

    from pressor.synthesis.problem.config import ConfigError
    from pressor.synthesis.problem.config_toml import load_config

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
            check_range(
                "--backoff: field 'solver.backoff'", args.backoff, 0.0, 1.0, error=UsageError
            )
            cfg = replace(cfg, solver=replace(cfg.solver, backoff=args.backoff))
    except ConfigError as exc:
        raise UsageError(str(exc)) from None

    out = Path(args.out)
    say(f"config {cfg.source}; grid {cfg.grid_points}; box {cfg.model.box.tolist()}")
    family = cfg.controller.impl
    given = {
        "--lambda-search": args.lambda_search,
        "--lambda2": args.lambda2 is not None,
        "--lambda3": args.lambda3 is not None,
        "--backoff": args.backoff is not None,
    }
    for option, was_given in given.items():
        if was_given and option not in family.synth_options:
            users = [s for s in structures() if option in family_named(s).synth_options]
            raise UsageError(
                f"{option}: an option of {', '.join(users)}, unused by structure {family.name!r}"
            )
    request = SynthRequest(
        frozenset(o for o, g in given.items() if g),
        args.lambda_search,
        args.jobs,
        args.scheduler,
    )
    designed = family.design(cfg, request, say)
    for note in designed.notes:  # said even with --quiet: the result depends on them
        print(f"pressor synth: {note}", file=sys.stderr)
    if designed.artifact is None:
        print(f"pressor synth: {designed.failure}", file=sys.stderr)
        return 1
    for line in designed.summary:
        print(line)
    return _verify_and_save(designed.artifact, out, args.no_verify, say, t0)


def _verify_and_save(
    art: ControllerArtifact, out: Path, no_verify: bool, say: Callable[[str], None], t0: float
) -> int:
    """Verify (unless ``no_verify``), store the verdict in the artifact, write it; the exit code."""
    from pressor.synthesis.artifact import save_artifact, with_verification

    verdict_code = 0
    if no_verify:
        print("verification     skipped (--no-verify)")
    else:
        from pressor.synthesis.verification.verify import verify_artifact

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
