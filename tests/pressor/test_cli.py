"""The console-script dispatcher: lazy imports and exit codes."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from pressor import cli


def test_unknown_command_is_usage_error_exit_2(capsys):
    assert cli.main(["no-such-command"]) == 2
    assert "unknown command" in capsys.readouterr().err


def test_help_lists_every_command(capsys):
    assert cli.main(["--help"]) == 0
    out = capsys.readouterr().out
    for name in cli.COMMANDS:
        assert name in out


def test_help_does_not_import_any_stage():
    code = (
        "import sys; from pressor import cli; cli.main(['--help']);"
        "bad=[m for m in ('pressor.synthesis','pressor.codegen','pressor.runtime','pressor.hil_sim','cvxpy','serial','rerun')"
        " if m in sys.modules]; print(bad); sys.exit(1 if bad else 0)"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_version_prints_the_installed_package_version(capsys):
    from importlib.metadata import version

    assert cli.main(["--version"]) == 0
    out = capsys.readouterr().out.strip()
    assert out == f"pressor {version('pressor')}" and out.split()[1][0].isdigit()


SPY_ON_NUMPY = """
import os, sys
seen = []
class Spy:
    def find_spec(self, name, path=None, target=None):
        if name == "numpy" and not seen:
            seen.append(os.environ.get("OPENBLAS_NUM_THREADS"))
        return None
sys.meta_path.insert(0, Spy())
import pytest

from pressor import cli
try:
    cli.main(sys.argv[1:])
except SystemExit:
    pass
print(seen)
"""


@pytest.mark.parametrize(
    "argv",
    # each fails only after its arguments parse, once numpy has loaded (--help loads no numpy)
    [
        ["synth", "--config", "no-such-design.toml"],
        ["verify", "--controller", "x:Y"],
        ["trial", "--out", "out", "--scenario", "no-such-scenario"],
    ],
)
def test_synthesis_and_trial_commands_pin_openblas_to_one_thread_before_numpy_loads(argv, tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    proc = subprocess.run(
        [sys.executable, "-c", SPY_ON_NUMPY, *argv],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        check=True,
    )
    # the value OpenBLAS reads when numpy loads it (a later setting has no effect)
    assert proc.stdout.strip().splitlines()[-1] == "['1']"


@pytest.mark.parametrize("command", ["faults", "scenarios"])
def test_a_reader_that_went_away_is_not_a_traceback(command):
    """``pressor faults | head``: the pipe's reader is gone before anything is written (closed
    here at once, so that every write meets it), and the command ends quietly with 0."""
    read_fd, write_fd = os.pipe()
    os.close(read_fd)
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "pressor", command],
            stdout=write_fd,
            stderr=subprocess.PIPE,
            text=True,
            env=dict(os.environ, CI="1"),
            timeout=60,
        )
    finally:
        os.close(write_fd)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr


#: modules whose import costs a command's --help tenths of a second or more: the numeric stack, the
#: solver, the recorder, the serial link and its dialect, plotting, and the shipped design's
#: generated controller (~0.7 MB of source)
HEAVY_MODULES = (
    "numpy",
    "scipy",
    "cvxpy",
    "rerun",
    "pandas",
    "serial",
    "pymavlink",
    "matplotlib",
    "pressor.runtime.generated.lpv_map_controller",
)

IMPORTS_AFTER = f"""
import sys
from pressor import cli
code = cli.main(sys.argv[1:])
print(code, [m for m in {HEAVY_MODULES!r} if m in sys.modules])
"""


@pytest.mark.parametrize("command", sorted(cli.COMMANDS))
@pytest.mark.parametrize(("extra", "exit_code"), [("--help", 0), ("--no-such-flag", 2)])
def test_help_and_argument_errors_of_every_command_import_no_heavy_module(
    command, extra, exit_code, tmp_path
):
    proc = subprocess.run(
        [sys.executable, "-c", IMPORTS_AFTER, command, extra],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == f"{exit_code} []", proc.stdout + proc.stderr
    if exit_code:
        # one line naming the command (argparse names a missing required option first)
        (line,) = proc.stderr.strip().splitlines()
        assert line.startswith(f"pressor {command}: "), line
    else:
        assert proc.stdout.startswith(f"usage: pressor {command}"), proc.stdout[:200]
