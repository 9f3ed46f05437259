"""The one usage-error path of every command (pressor.plumbing.usage): one line on stderr, exit 2."""

from __future__ import annotations

import pytest

from pressor.plumbing.usage import USAGE_EXIT, UsageError, UsageParser, run_command


def _parser() -> UsageParser:
    p = UsageParser(prog="pressor demo")
    p.add_argument("--rate", type=float, default=10.0, help="loop rate in Hz (default 10)")
    return p


def test_a_parser_error_raises_usage_error_instead_of_printing_and_exiting():
    with pytest.raises(UsageError, match="argument --rate: invalid float value: 'fast'"):
        _parser().parse_args(["--rate", "fast"])


def test_run_command_prints_one_line_with_the_program_and_returns_2(capsys):
    def handler(argv):
        _parser().parse_args(argv)
        raise UsageError("--rate 0: allowed (0, 1000] Hz")

    assert run_command("pressor demo", handler, ["--rate", "0"]) == USAGE_EXIT == 2
    assert capsys.readouterr().err == "pressor demo: --rate 0: allowed (0, 1000] Hz\n"
    assert run_command("pressor demo", handler, ["--bogus"]) == 2
    assert capsys.readouterr().err == "pressor demo: unrecognized arguments: --bogus\n"


def test_run_command_passes_the_handlers_code_and_help_exits_0(capsys):
    assert run_command("pressor demo", lambda argv: 1, []) == 1
    assert run_command("pressor demo", lambda argv: _parser().parse_args(argv) and 0, ["-h"]) == 0
    out = capsys.readouterr()
    assert "loop rate in Hz (default 10)" in out.out and out.err == ""
