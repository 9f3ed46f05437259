"""The terminal status line of a run: drawn on a real terminal, silent on a pipe or file."""

from __future__ import annotations

import io
import os
import select

from pressor.runtime.shell.progress import TerminalProgress


def read_all(fd: int) -> str:
    """Everything written to the terminal so far (it arrives in pieces)."""
    data = b""
    while select.select([fd], [], [], 0.5)[0]:
        data += os.read(fd, 65536)
    return data.decode()


def drive(progress: TerminalProgress, ticks: int) -> None:
    for k in range(ticks):
        progress(k, 1, 0, 0.0)


def test_status_line_shows_sim_time_share_and_real_time_factor():
    p = TerminalProgress(0.1, total_ticks=36000, stream=io.StringIO())
    assert p.line(9000, 2.0) == "sim 15:00 / 1:00:00 (25 %)  450x real time"
    assert TerminalProgress(0.1).line(600, 0.0) == "sim 1:00"


def test_progress_is_drawn_on_a_real_terminal_and_cleared_at_the_end():
    leader, follower = os.openpty()
    try:
        with os.fdopen(follower, "w", closefd=False) as tty:
            p = TerminalProgress(0.1, total_ticks=1000, stream=tty, interval_s=0.0, check_every=100)
            assert p.enabled
            drive(p, 1000)
            p.close()
        text = read_all(leader)
    finally:
        os.close(leader)
        os.close(follower)
    assert text.count("\rsim ") == 9  # one redraw per 100 ticks after the first (clock start)
    assert "\rsim 1:30 / 1:40 (90 %)" in text  # the last redraw: tick 900 -> 901 ticks
    assert "x real time" in text
    assert text.endswith("\r\033[K")


def test_progress_writes_nothing_when_stderr_is_not_a_terminal():
    out = io.StringIO()
    p = TerminalProgress(0.1, total_ticks=1000, stream=out, interval_s=0.0, check_every=1)
    assert not p.enabled
    drive(p, 1000)
    p.close()
    assert out.getvalue() == ""
