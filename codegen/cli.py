"""``pressor codegen [ARTIFACT] --target python|c [--fixed-point q15|q31] --out DIR``.

ARTIFACT defaults to the shipped default design. Exit codes: 0 written (or already up to date),
2 bad usage, bad artifact or unwritable output directory (one line naming file, field and value).

Progress goes to stderr (stdout carries only the ``wrote``/``unchanged`` lines): one line per stage
and, inside the long ones (tabulate, quantise: seconds to a minute), the counts of work done at most
every ``PROGRESS_INTERVAL_S``: one line each when stderr is a file or a pipe, one line redrawn in
place (carriage return) when it is a terminal.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TextIO

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


#: Shortest wall time (s) between two progress lines inside a stage.
PROGRESS_INTERVAL_S = 1.0


class StageProgress:
    """Stage lines and throttled in-stage counts on a stream (stderr).

    Parameters
    ----------
    stream
        Where to write; a terminal (``isatty``) gets the counts redrawn on one line, anything
        else one line per shown count.
    interval_s
        Shortest wall time (s) between two shown counts (the first one after a stage line too).
    clock
        Monotonic seconds.
    """

    def __init__(
        self,
        stream: TextIO,
        interval_s: float = PROGRESS_INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.stream = stream
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        self.interval_s = float(interval_s)
        self.clock = clock
        self._last = clock()
        self._open = False  # a redrawn count is on the terminal's current line

    def line(self, msg: str) -> None:
        """A stage line (always shown; ends a redrawn count line first)."""
        self.finish()
        print(msg, file=self.stream, flush=True)
        self._last = self.clock()

    def update(self, msg: str) -> None:
        """A count inside a stage: shown when ``interval_s`` has passed since the last line."""
        now = self.clock()
        if now - self._last < self.interval_s:
            return
        self._last = now
        if self.tty:
            self.stream.write("\r\033[K" + msg)
            self.stream.flush()
            self._open = True
        else:
            print(msg, file=self.stream, flush=True)

    def finish(self) -> None:
        """End a redrawn count line (before anything else is written to the stream)."""
        if self._open:
            self.stream.write("\r\033[K")
            self._open = False


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
    shown = StageProgress(sys.stderr)
    try:
        paths, skipped = generate(
            args.artifact,
            args.target,
            out,
            fmt=args.fixed_point,
            c_float=args.c_float,
            progress=shown.line,
            update=shown.update,
        )
    except CodegenError as exc:
        shown.finish()
        raise UsageError(str(exc)) from None
    except OSError as exc:
        shown.finish()
        raise UsageError(f"--out {out}: cannot write ({exc})") from None
    for p in paths:
        print(f"{'unchanged' if skipped else 'wrote'} {p}")
    return 0
