"""Graceful stop of the long-running commands (``pressor run``, ``sil``, ``device``) on SIGINT /
SIGTERM.

:func:`stop_on_signals` replaces the default handlers (a ``KeyboardInterrupt`` traceback, or death
by SIGTERM with hidden temporary files left behind) by one that only records the signal. The loops
poll :func:`stop_requested` between ticks and while they wait, stop at a tick boundary (the runtime
commands the safe rate first), and the command then closes its ``.rrd`` / ``.tlog`` as valid files,
writes its summary marked ``"interrupted": true`` and exits with :func:`exit_code` (130 for SIGINT,
143 for SIGTERM, the shell's 128 + signal number) after one line on stderr.
"""

from __future__ import annotations

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


@contextmanager
def stop_on_signals() -> Iterator[None]:
    """Within the block, SIGINT and SIGTERM only set :func:`stop_requested`.

    Outside the main thread (where Python cannot install handlers) the block changes nothing.
    The previous handlers are restored on exit.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _received.clear()
    previous = {s: signal.signal(s, _record) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
