"""Graceful stop of the long-running commands (``pressor run``, ``sil``, ``device``) on SIGINT /
SIGTERM.

:func:`stop_on_signals` replaces the default handlers (a ``KeyboardInterrupt`` traceback, or death
by SIGTERM with hidden temporary files left behind) by one that only records the signal. The loops
poll :func:`stop_requested` between ticks and while they wait, stop at a tick boundary (the runtime
commands the safe rate first), and the command then closes its ``.rrd`` / ``.tlog`` as valid files,
writes its summary marked ``"interrupted": true`` and exits with :func:`exit_code` (130 for SIGINT,
143 for SIGTERM, the shell's 128 + signal number) after one line on stderr.  While such a command
starts (its imports, its options, its key: nothing to keep yet) :func:`arm_early`'s handler ends
it at once with one line (``interrupted by SIGINT before the run started``); :func:`begin_run`,
called before it opens a port or starts a process, hands over to the graceful stop.
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

#: the signals that ask for a graceful stop
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)

_received: list[int] = []


class Interrupted(Exception):
    """A stop signal arrived before the run started (nothing to keep); carries its number."""

    def __init__(self, signum: int, where: str) -> None:
        super().__init__(f"interrupted by {signal.Signals(signum).name} {where}")
        self.signum = signum


def stop_requested() -> int | None:
    """The stop signal received since :func:`stop_on_signals` was entered, else ``None``."""
    return _received[0] if _received else None


def exit_code(signum: int) -> int:
    """The exit status of a command stopped by ``signum``: 128 + its number (130, 143)."""
    return 128 + int(signum)


def signal_name(signum: int) -> str:
    """``SIGINT`` / ``SIGTERM`` for a signal number."""
    return signal.Signals(signum).name


def _record(signum: int, _frame: object) -> None:
    if not _received:
        _received.append(signum)


def _exit_now(signum: int, _frame: object) -> None:
    """The start-up handler (:func:`arm_early`): nothing to keep yet, so one line and exit."""
    prog = _starting[0] if _starting else "pressor"
    line = f"{prog}: interrupted by {signal_name(signum)} before the run started\n"
    os.write(2, line.encode())
    os._exit(exit_code(signum))


#: the command whose start-up :func:`arm_early` guards (empty when not armed)
_starting: list[str] = []
#: the handlers :func:`arm_early` replaced, restored after a run it handed over
_before_arming: dict[int, object] = {}


def arm_early(prog: str) -> None:
    """Until :func:`begin_run`, SIGINT and SIGTERM end the command at once: one line
    ``PROG: interrupted by SIGINT before the run started`` and exit 130 (143).

    For the start of a long-running command (``pressor run``, ``sil``, ``device``), called before
    its imports: until it opens a port or starts a process it has nothing to keep or undo, so a
    Ctrl-C while it loads ends it within the second, never as a ``KeyboardInterrupt`` traceback
    (nor lost in a module's broad ``except``). A :func:`stop_on_signals` block entered meanwhile
    leaves this handler in place until :func:`begin_run`. Outside the main thread it does
    nothing.
    """
    if threading.current_thread() is threading.main_thread():
        _starting[:] = [prog]
        for s in STOP_SIGNALS:
            previous = signal.signal(s, _exit_now)
            if previous is not _exit_now:
                _before_arming[s] = previous


def begin_run() -> None:
    """The command is about to open a port or start a process: from now on a stop signal is a
    graceful stop request (:func:`stop_requested`, checked at tick boundaries and while waiting).
    Does nothing unless :func:`arm_early` armed the start-up handler."""
    if threading.current_thread() is threading.main_thread() and _starting:
        _starting.clear()
        for s in STOP_SIGNALS:
            if signal.getsignal(s) is _exit_now:
                signal.signal(s, _record)


@contextmanager
def stop_on_signals() -> Iterator[None]:
    """Within the block, SIGINT and SIGTERM only set :func:`stop_requested` (while a command
    starts, :func:`arm_early`'s handler stays until :func:`begin_run`).

    Outside the main thread (where Python cannot install handlers) the block changes nothing.
    The previous handlers are restored on exit.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _received.clear()
    handler = _exit_now if _starting else _record
    previous = {s: signal.signal(s, handler) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, before in previous.items():
            if before is _exit_now and not _starting:  # the run began: not "before the run"
                before = _before_arming.get(s, signal.SIG_DFL)
            signal.signal(s, before)  # type: ignore[arg-type]
