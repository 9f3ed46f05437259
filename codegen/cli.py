"""``pressor codegen [ARTIFACT] --target python|c [--fixed-point q15|q31] --out DIR``.

ARTIFACT defaults to the shipped default design. Exit codes: 0 written (or already up to date),
2 bad usage, bad artifact or unwritable output directory (one line naming file, field and value).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from pathlib import Path

from pressor.plumbing.usage import UsageError, UsageParser, run_command


def _parser() -> UsageParser:
    from pressor.synthesis.artifact_path import default_artifact_path  # not the pipeline: numpy

    p = UsageParser(
        prog="pressor codegen",
        description="Emit a standalone scheduled LPV controller (Python or C99) from an artifact.",
    )
    p.add_argument(
        "artifact",
        nargs="?",
        default=str(default_artifact_path()),
        help="artifact .npz (default: shipped)",
    )
    p.add_argument(
        "--target", choices=("python", "c"), required=True, help="language of the emitted module"
    )
    p.add_argument(
        "--fixed-point",
        choices=("q15", "q31"),
        default="q31",
        dest="fixed_point",
        help="integer data path word: q15 (16-bit) or q31 (32-bit) fixed point",
    )
    p.add_argument(
        "--c-float",
        action="store_true",
        help="C target: emit the double-precision step instead of fixed point",
    )
    p.add_argument("--out", required=True, help="output directory")
    return p


def _check_out_dir(out: Path) -> str | None:
    probe = out
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        return f"--out {out}: {probe} is not a directory"
    if not os.access(probe, os.W_OK | os.X_OK):
        return f"--out {out}: directory {probe} is not writable"
    return None


def main(command: str, argv: list[str]) -> int:
    """Run ``pressor codegen``; see the module docstring for the exit codes."""
    return run_command(f"pressor {command}", _codegen, argv)


def _codegen(argv: Sequence[str]) -> int:
    args = _parser().parse_args(argv)
    from pressor.codegen.pipeline import CodegenError, generate

    out = Path(args.out)
    err = _check_out_dir(out)
    if err:
        raise UsageError(err)
    try:
        paths, skipped = generate(
            args.artifact,
            args.target,
            out,
            fmt=args.fixed_point,
            c_float=args.c_float,
            progress=lambda m: print(m, file=sys.stderr),
        )
    except CodegenError as exc:
        raise UsageError(str(exc)) from None
    except OSError as exc:
        raise UsageError(f"--out {out}: cannot write ({exc})") from None
    for p in paths:
        print(f"{'unchanged' if skipped else 'wrote'} {p}")
    return 0
