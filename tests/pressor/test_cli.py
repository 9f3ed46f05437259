"""The console-script dispatcher: lazy imports and exit codes."""

from __future__ import annotations

import subprocess
import sys

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
        "bad=[m for m in ('synthesis','codegen','runtime','sim','cvxpy','serial','rerun')"
        " if m in sys.modules]; print(bad); sys.exit(1 if bad else 0)"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_version_prints_the_installed_package_version(capsys):
    from importlib.metadata import version

    assert cli.main(["--version"]) == 0
    out = capsys.readouterr().out.strip()
    assert out == f"pressor {version('pressor')}" and out.split()[1][0].isdigit()
