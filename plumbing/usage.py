"""Bad usage or input on a command line: one exception, one exit code, one line on stderr.

Every ``pressor`` command reports a bad option, a bad value or an unreadable input the same way:
one line ``PROG: MESSAGE`` on stderr, naming the option or file, the value and the allowed range,
and exit code :data:`USAGE_EXIT` (docs/INTERFACES.md, "CLI"). A command raises
:class:`UsageError` wherever it finds the problem, parses its options with :class:`UsageParser`
(whose errors are :class:`UsageError` too, not argparse's usage block), and runs under
:func:`run_command`, which turns the exception into that line and that code.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable, Sequence
from typing import Any, NoReturn, TextIO

#: exit code of bad usage or bad input
USAGE_EXIT = 2


class UsageError(Exception):
    """Bad usage or input; the message is one line naming the option or file, the value and the
    allowed range (without the program name, which :func:`run_command` puts in front)."""


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """Help that shows every option's default: ``(default: VALUE)`` is appended to an option's
    help unless the help already says what its default is (the word "default"); a required
    option's reads ``(required)``. A flag's default
    reads ``off``; an option without a value (``None``, an empty list) reads ``none``."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if not action.option_strings or action.default is argparse.SUPPRESS:
            return text
        if re.search(r"\bdefault\b", text, re.IGNORECASE):
            return text
        if action.required:
            return f"{text} (required)".lstrip()
        value = action.default
        if isinstance(action, argparse._StoreTrueAction):
            shown = "off"
        elif value is None or value == []:
            shown = "none"
        else:
            shown = str(value).replace("%", "%%")
        return f"{text} (default: {shown})".lstrip()


class UsageParser(argparse.ArgumentParser):
    """An :class:`argparse.ArgumentParser` whose errors raise :class:`UsageError`.

    argparse's own error prints the usage block and exits; this one leaves the reporting to
    :func:`run_command`, so a bad option gives the same one line as any other bad input.
    ``--help`` still prints the help and raises :class:`SystemExit` (code 0); it shows every
    option's default (:class:`DefaultsHelpFormatter`).
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", DefaultsHelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        """Raise :class:`UsageError` with argparse's message (e.g. ``argument --rate: ...``)."""
        raise UsageError(message)


def usage_exit(prog: str, message: object, file: TextIO | None = None) -> int:
    """Print ``PROG: MESSAGE`` as one line on ``file`` (default stderr); return :data:`USAGE_EXIT`.

    Parameters
    ----------
    prog
        The command, e.g. ``pressor sil``.
    message
        What was wrong (a :class:`UsageError` or text).
    file
        Where to print; ``sys.stderr`` when omitted.
    """
    print(f"{prog}: {message}", file=sys.stderr if file is None else file)
    return USAGE_EXIT


def run_command(prog: str, handler: Callable[[Sequence[str]], int], argv: Sequence[str]) -> int:
    """Run ``handler(argv)`` with the usage exit: :class:`UsageError` gives one line and code 2.

    Parameters
    ----------
    prog
        The command name printed in front of a usage error.
    handler
        Parses ``argv`` and runs the command; returns its exit code.
    argv
        The command's arguments.

    Returns
    -------
    int
        ``handler``'s code; :data:`USAGE_EXIT` after a :class:`UsageError`; the code of a
        :class:`SystemExit` (``--help``: 0).
    """
    try:
        return handler(argv)
    except UsageError as exc:
        return usage_exit(prog, exc)
    except SystemExit as exc:  # argparse --help
        return int(exc.code or 0)


def parse_first(prog: str, parser: argparse.ArgumentParser, argv: Sequence[str]) -> int | None:
    """Parse ``argv`` before a command imports what its run needs: ``--help`` and bad options
    answer at once, without numpy, the link or the recorder loaded.

    The command parses ``argv`` again when it runs (the parse is cheap and has no side effects);
    this call only decides whether it runs at all.

    Parameters
    ----------
    prog
        The command name printed in front of a usage error.
    parser
        The command's parser (a :class:`UsageParser`, or any parser that raises
        :class:`UsageError` or :class:`SystemExit`).
    argv
        The command's arguments.

    Returns
    -------
    int or None
        The exit code when the command ends here (``--help``: 0; a usage error: one line on
        stderr and :data:`USAGE_EXIT`); ``None`` when ``argv`` parses and the command should run.
    """
    try:
        parser.parse_args(argv)
    except UsageError as exc:
        return usage_exit(prog, exc)
    except SystemExit as exc:  # argparse --help
        return int(exc.code or 0)
    return None
