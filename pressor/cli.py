"""The ``pressor`` console script: a small dispatcher over the stages' own CLIs.

Each stage owns its subcommands in its own ``cli.py`` (docs/INTERFACES.md, "CLI"); ``pressor sil``,
which needs both ends of the link, is served by the front door itself (:mod:`pressor.sil`). This
module only knows which module serves which subcommand and imports that module when, and only
when, the subcommand runs: ``pressor run`` never loads the solver, ``pressor synth`` never loads
serial or rerun.

A stage CLI module exposes ``main(command: str, argv: list[str]) -> int`` and parses ``argv`` itself.
Exit codes: 0 success, 1 the run completed but a check failed, 2 bad usage or bad input
(:mod:`pressor.plumbing.usage`).
"""

from __future__ import annotations

import importlib
import os
import signal
import sys

from pressor.plumbing.usage import USAGE_EXIT, usage_exit

#: subcommand -> (module that serves it, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "synth": ("pressor.synthesis.cli", "synthesize, verify and write a controller artifact"),
    "verify": (
        "pressor.verify",
        "independent checks of an artifact (default: the shipped design) or a plugin's step",
    ),
    "codegen": (
        "pressor.codegen.cli",
        "emit a standalone scheduled controller (python or C) from an artifact",
    ),
    "scenarios": ("pressor.hil_sim.cli", "list the named SIL scenarios"),
    "patients": ("pressor.listing", "list the simulated patient models: drug, what, source"),
    "designs": ("pressor.listing", "list the shipped controller designs and baselines"),
    "trial": ("pressor.hil_sim.cli", "in-silico cohort trial of a controller on seeded patients"),
    "device": (
        "pressor.hil_sim.devices.device",
        "run the simulated patient/pump/monitor device on a serial port",
    ),
    "sil": ("pressor.sil", "software-in-the-loop run: device process + runtime over a serial link"),
    "run": ("pressor.runtime.cli", "run the controller runtime alone on a serial port"),
    "faults": ("pressor.runtime.cli", "list the injectable fault kinds"),
    "keygen": (
        "pressor.runtime.cli",
        "write a link signing key for pressor run and pressor device",
    ),
}


#: the offline commands whose many small dense problems (delay-system eigenvalues, LMI blocks) run
#: fastest on one OpenBLAS thread, and the cohort trial, whose patients make a few tiny BLAS calls
#: each after which OpenBLAS' idle threads spin on another core (≈ 13 % more CPU time per patient,
#: docs/notes/benchmarks.md, "Trial throughput"); its worker processes inherit the pin. The pin must
#: come before numpy's import, which importing the command's module already triggers
#: (:mod:`pressor.synthesis.solver.blas_threads`)
ONE_BLAS_THREAD = frozenset({"synth", "verify", "trial"})
#: the long-running bedside commands that stop gracefully on SIGINT / SIGTERM
#: (:mod:`pressor.runtime.shell.interrupt`): their handler is installed before their imports
STOPPABLE = frozenset({"run", "sil", "device"})


def _usage() -> str:
    width = max(len(name) for name in COMMANDS)
    lines = ["usage: pressor COMMAND [ARGS...]", "", "commands:"]
    lines += [f"  {name:<{width}}  {text}" for name, (_, text) in COMMANDS.items()]
    lines += [
        "",
        "'pressor COMMAND --help' shows a command's options; 'pressor --version' the version.",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Dispatch ``pressor COMMAND ...`` to the stage that owns COMMAND.

    Parameters
    ----------
    argv
        Arguments after the program name; ``sys.argv[1:]`` when omitted.

    Returns
    -------
    int
        The process exit code (0 ok, 1 a check failed, 2 bad usage or input).
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help", "help"):
        print(_usage())
        return 0 if args else USAGE_EXIT
    if args[0] in ("--version", "-V"):
        from importlib.metadata import version  # ~20 ms: only for --version

        print(f"pressor {version('pressor')}")
        return 0
    command, rest = args[0], args[1:]
    if command not in COMMANDS:
        return usage_exit("pressor", f"unknown command {command!r}; one of: {', '.join(COMMANDS)}")
    if command in STOPPABLE:  # before its imports: a Ctrl-C while they load is a stop request
        from pressor.runtime.shell.interrupt import arm_early

        arm_early(f"pressor {command}")
    if command in ONE_BLAS_THREAD:
        from pressor.synthesis.solver.blas_threads import single_blas_thread

        single_blas_thread()
    try:
        module = importlib.import_module(COMMANDS[command][0])
        return int(module.main(command, rest))
    except KeyboardInterrupt:  # a command that does not stop gracefully: one line, no traceback
        print(f"pressor {command}: interrupted by SIGINT", file=sys.stderr)
        return 128 + signal.SIGINT
    except BrokenPipeError:
        # the reader went away (`pressor faults | head`): what it wanted it has; say nothing, and
        # keep the interpreter's own flush of stdout at exit from raising again
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
