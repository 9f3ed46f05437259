"""The runtime's live MAP target: stdin lines over a real pipe, a target file on disk."""

from __future__ import annotations

import io
import os
from pathlib import Path

import pytest

from pressor.runtime.inputs.clinician import ClinicianInput
from pressor.runtime.inputs.target_source import TargetSource
from tests.support.link_doubles import tick_inputs


class EventLog:
    """Collects what the source logs to the recording (``Recorder.event``'s signature)."""

    def __init__(self) -> None:
        self.events: list[tuple[int, str, bool]] = []

    def event(
        self, tick: int, sim_time_s: float, text: str, warn: bool = True, **_: object
    ) -> None:
        self.events.append((tick, text, warn))


def _tick(source: TargetSource, k: int, log: EventLog | None = None) -> float:
    inp = tick_inputs(k, 0.1 * k, 60.0, target_mmhg=80.0)
    out = source.apply(inp, log)
    assert (out.tick, out.map_mmhg, out.K, out.target_tick) == (k, 60.0, inp.K, k)
    return out.target_mmhg


@pytest.fixture
def pipe():
    r, w = os.pipe()
    yield r, w
    for fd in (r, w):
        try:
            os.close(fd)
        except OSError:
            pass


def test_stdin_lines_change_the_target_at_the_next_tick_and_bad_ones_are_refused(pipe):
    r, w = pipe
    err = io.StringIO()
    log = EventLog()
    src = TargetSource(ClinicianInput(target_mmhg=70.0, target_stdin=True), stdin_fd=r, err=err)
    assert _tick(src, 0, log) == 70.0
    os.write(w, b"85\n9")  # a whole line and the start of the next
    assert _tick(src, 1, log) == 85.0
    os.write(w, b"0\n\nabc\n")  # completes 90; a blank line is ignored; abc is refused
    assert _tick(src, 2, log) == 90.0
    assert _tick(src, 3, log) == 90.0
    os.write(w, b"130\n")
    assert _tick(src, 4, log) == 90.0
    os.write(w, b"60")
    os.close(w)  # the end of input ends the last line; the target stays
    assert _tick(src, 5, log) == 60.0
    assert _tick(src, 6, log) == 60.0
    assert [(c["tick"], c["old_mmhg"], c["new_mmhg"], c["from"]) for c in src.changes] == [
        (1, 70.0, 85.0, "stdin"),
        (2, 85.0, 90.0, "stdin"),
        (5, 90.0, 60.0, "stdin"),
    ]
    assert src.refused == 2
    lines = err.getvalue().splitlines()
    assert lines == [
        "pressor run: target from stdin refused: 'abc': must be a finite number in [50, 120] mmHg;"
        " keeping 90 mmHg",
        "pressor run: target from stdin refused: '130' = 130.0: must be a finite number in [50, 120] mmHg; keeping 90 mmHg",
    ]
    assert log.events[0][:2] == (
        0,
        "target 70 mmHg from the runtime; the device's MAP_TARGET is ignored",
    )
    assert (1, "target 70 -> 85 mmHg (stdin)", False) in log.events
    assert (2, lines[0].removeprefix("pressor run: "), True) in log.events
    assert src.summary() == {
        "source": "runtime",
        "initial_mmhg": 70.0,
        "changes": src.changes,
        "refused": 2,
        "acks": [],
    }


def _replace(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def test_a_target_file_is_reread_only_when_it_changes(tmp_path):
    path = tmp_path / "target"
    path.write_text("70\n")
    err = io.StringIO()
    src = TargetSource(ClinicianInput(target_mmhg=70.0, target_file=path), err=err)
    assert _tick(src, 0) == 70.0 and src.changes == []  # the starting content is no change
    _replace(path, "70\n")
    assert _tick(src, 1) == 70.0 and src.changes == []  # nor is the same target rewritten
    _replace(path, "75.5\n")
    assert _tick(src, 2) == 75.5
    assert _tick(src, 3) == 75.5 and len(src.changes) == 1
    path.write_text("")  # a writer that truncates first: ignored, nothing refused
    assert _tick(src, 4) == 75.5
    path.write_text("88")
    assert _tick(src, 5) == 88.0
    path.unlink()
    assert _tick(src, 6) == 88.0
    assert src.refused == 1
    assert "cannot read" in err.getvalue() and "keeping 88 mmHg" in err.getvalue()
    _replace(path, "91\n")
    assert _tick(src, 7) == 91.0
    assert [c["tick"] for c in src.changes] == [2, 5, 7]
    assert {c["from"] for c in src.changes} == {f"file {path}"}


def test_a_target_file_changed_before_the_loop_started_is_applied_at_the_first_tick(tmp_path):
    path = tmp_path / "target"
    path.write_text("72\n")  # the command line read 70; the file changed during the handshake
    src = TargetSource(ClinicianInput(target_mmhg=70.0, target_file=path), err=io.StringIO())
    assert _tick(src, 0) == 72.0
    assert [(c["tick"], c["old_mmhg"], c["new_mmhg"]) for c in src.changes] == [(0, 70.0, 72.0)]
