"""CLI latency: wall time of ``pressor COMMAND --help`` and of an argument error, per subcommand.

Each command is run as a fresh process (``python -m pressor COMMAND ...``, what the console script
does) several times; the table gives the median wall time in seconds and the exit codes. The target
is under 0.5 s for every row: the stages import numpy, scipy, cvxpy, rerun, pandas, serial only
after the arguments are read (docs/notes/benchmarks.md, "CLI latency"). With
``PYTHONDONTWRITEBYTECODE`` set every import compiles its source, the slower case; the header line
says which case ran.
Usage::

    python -m benchmarks.cli_latency [--runs 5] [--commands sil,trial,...]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

#: every subcommand of ``pressor`` (pressor.cli.COMMANDS), in the order the table lists them
COMMANDS: tuple[str, ...] = (
    "sil",
    "trial",
    "run",
    "device",
    "synth",
    "verify",
    "codegen",
    "faults",
    "scenarios",
    "keygen",
)

#: the two invocations measured per subcommand: its help, and an option no command has
CASES: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("--help", ("--help",)),
    ("bad flag", ("--no-such-flag",)),
)

#: the bound every row must meet, in seconds
TARGET_S = 0.5


def time_command(argv: list[str], runs: int) -> tuple[float, int]:
    """Median wall time of ``python -m pressor *argv`` over ``runs`` fresh processes.

    Parameters
    ----------
    argv
        Arguments after ``pressor``.
    runs
        How many processes to time.

    Returns
    -------
    tuple[float, int]
        The median wall time in seconds and the exit code of the last run.
    """
    times: list[float] = []
    code = 0
    for _ in range(runs):
        start = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, "-m", "pressor", *argv],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            check=False,
        )
        times.append(time.perf_counter() - start)
        code = proc.returncode
    return statistics.median(times), code


def main() -> None:
    """Print the latency table as markdown."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=5, help="processes timed per row (default 5)")
    p.add_argument(
        "--commands",
        default=",".join(COMMANDS),
        help="comma-separated subcommands to time (default: all)",
    )
    args = p.parse_args()
    commands = [c for c in args.commands.split(",") if c]
    baseline, _ = time_command(["--version"], args.runs)
    cache = "off" if os.environ.get("PYTHONDONTWRITEBYTECODE") else "on"
    print(
        f"python {sys.version.split()[0]}, bytecode cache writes {cache};"
        f" `pressor --version`: {baseline:.3f} s (median of {args.runs})"
    )
    print()
    print("| command | `--help` (s) | `--no-such-flag` (s) | exit codes |")
    print("|---|---|---|---|")
    slow = 0
    for command in commands:
        cells: list[str] = []
        codes: list[str] = []
        for _, extra in CASES:
            seconds, code = time_command([command, *extra], args.runs)
            slow += seconds >= TARGET_S
            cells.append(f"{seconds:.3f}" if seconds < TARGET_S else f"**{seconds:.3f}**")
            codes.append(str(code))
        print(f"| `{command}` | {cells[0]} | {cells[1]} | {', '.join(codes)} |")
    print()
    print(f"{slow} of {2 * len(commands)} rows at or above {TARGET_S} s (bold)")


if __name__ == "__main__":
    main()
