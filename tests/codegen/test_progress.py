"""``pressor codegen`` shows how far its long stages are (stderr), without touching what it writes.

The command runs for real on the shipped design (its tabulate stage takes seconds to a minute), as
a separate process whose stderr is a pipe: one line per shown count.
"""

from __future__ import annotations

import io
import re
import subprocess
import sys
from pathlib import Path

import pytest

from pressor.codegen import pipeline as pl
from pressor.codegen.cli import StageProgress
from tests.support.generated_currency import assert_same_bytes

COMMITTED_C = [
    Path(pl.REPO_ROOT) / "runtime" / "generated" / f"lpv_map_controller{ext}"
    for ext in (".h", ".c")
]
COUNT = re.compile(
    r"^stage 2/4 tabulate: round (\d+), grid (\d+)x(\d+)x(\d+): "
    r"(nodes|edge midpoints|cell checks) (\d+)/(\d+)$"
)


@pytest.fixture(scope="module")
def codegen_run(tmp_path_factory):
    if not pl.DEFAULT_ARTIFACT.is_file():
        pytest.skip("no shipped design")
    out = tmp_path_factory.mktemp("progress")
    cmd = [sys.executable, "-m", "pressor", "codegen", str(pl.DEFAULT_ARTIFACT)]
    run = subprocess.run(
        [*cmd, "--target", "c", "--c-float", "--out", str(out)],
        capture_output=True, text=True, timeout=900, check=False,
    )  # fmt: skip
    return run, out


@pytest.mark.slow  # a real 15 s codegen; the two below check the progress itself
def test_tabulate_stage_reports_its_counts_line_by_line_on_stderr(codegen_run):
    run, _ = codegen_run
    assert run.returncode == 0, run.stderr
    err = run.stderr.splitlines()
    counts = [m for line in err if (m := COUNT.match(line))]
    assert len(counts) >= 2, err
    for m in counts:
        assert 1 <= int(m.group(6)) <= int(m.group(7))
    rounds = [int(m.group(1)) for m in counts]
    assert rounds == sorted(rounds)
    assert "\r" not in run.stderr  # not a terminal: no redrawing
    stages = [line.split(":")[0] for line in err if line.startswith("stage ") and " " in line]
    assert [s for i, s in enumerate(stages) if s not in stages[:i]] == [
        "stage 1/4 load",
        "stage 2/4 tabulate",
        "stage 3/4 quantise",
        "stage 4/4 emit",
    ]


@pytest.mark.slow  # the same real codegen run
def test_progress_leaves_stdout_and_the_written_files_as_without_it(codegen_run):
    run, out = codegen_run
    assert run.stdout.splitlines() == [f"wrote {out / p.name}" for p in COMMITTED_C]
    for committed in COMMITTED_C:
        assert_same_bytes(out / committed.name, committed)


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


class _Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_a_terminal_gets_the_counts_redrawn_in_place_and_stage_lines_after_them():
    term, clock = _Terminal(), _Clock()
    shown = StageProgress(term, interval_s=1.0, clock=clock)
    shown.line("stage 2/4 tabulate: start")
    for i in range(1, 31):
        clock.t = i * 0.1
        shown.update(f"stage 2/4 tabulate: nodes {i}/30")
    shown.line("stage 3/4 quantise: next")
    text = term.getvalue()
    assert text.count("\n") == 2  # only the two stage lines end a line
    assert text.count("\r\033[K") == 4  # 3 counts (at 1 s, 2 s, 3 s) and their erasure
    assert "\r\033[Kstage 2/4 tabulate: nodes 10/30" in text
    assert text.endswith("\r\033[Kstage 3/4 quantise: next\n")


def test_counts_are_shown_at_most_once_per_interval():
    pipe, clock = io.StringIO(), _Clock()
    shown = StageProgress(pipe, interval_s=2.0, clock=clock)
    for i in range(1000):
        clock.t = i * 0.01  # 10 s of updates, 100 a second
        shown.update(f"n {i}")
    lines = pipe.getvalue().splitlines()
    assert lines == ["n 200", "n 400", "n 600", "n 800"]
