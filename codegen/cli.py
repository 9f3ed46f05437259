"""``pressor codegen [ARTIFACT] --target python|c [--fixed-point q15|q31] --out DIR``.

ARTIFACT defaults to the shipped default design. Exit codes: 0 written (or already up to date),
2 bad usage, bad artifact or unwritable output directory (one line naming file, field and value).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path


def _parser() -> argparse.ArgumentParser:
    from codegen.pipeline import DEFAULT_ARTIFACT

    p = argparse.ArgumentParser(
        prog="pressor codegen",
        description="Emit a standalone scheduled LPV controller (Python or C99) from an artifact.",
    )
    p.add_argument(
        "artifact",
        nargs="?",
        default=str(DEFAULT_ARTIFACT),
        help="artifact .npz (default: shipped)",
    )
    p.add_argument("--target", choices=("python", "c"), required=True)
    p.add_argument("--fixed-point", choices=("q15", "q31"), default="q31", dest="fixed_point")
    p.add_argument(
        "--c-float", action="store_true", help="C target: emit the double-precision step instead"
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
    try:
        args = _parser().parse_args(argv)
    except SystemExit as exc:
        return 0 if exc.code == 0 else 2
    from codegen.pipeline import CodegenError, generate

    out = Path(args.out)
    err = _check_out_dir(out)
    if err:
        print(f"pressor codegen: {err}", file=sys.stderr)
        return 2
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
        print(f"pressor codegen: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"pressor codegen: --out {out}: cannot write ({exc})", file=sys.stderr)
        return 2
    for p in paths:
        print(f"{'unchanged' if skipped else 'wrote'} {p}")
    return 0
