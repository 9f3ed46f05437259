"""pressor.plumbing.parallel's local pool: task order, a task's own error, a worker that dies."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import time

import pytest

from pressor.plumbing.parallel import run_ordered


def _slow_square(x: int) -> int:
    time.sleep(0.01 * (x % 3))  # finish out of order
    return x * x


def _fails_on_three(x: int) -> int:
    if x == 3:
        raise ValueError(f"task {x} refused")
    return x


def test_two_workers_return_every_result_in_task_order_with_progress():
    seen = []
    out = run_ordered(
        _slow_square, list(range(12)), jobs=2, progress=lambda d, n: seen.append((d, n))
    )
    assert out == [x * x for x in range(12)]
    assert seen == [(i, 12) for i in range(1, 13)]


def test_a_tasks_own_error_reaches_the_caller_as_itself_and_stops_the_rest():
    t0 = time.monotonic()
    with pytest.raises(ValueError, match="task 3 refused"):
        run_ordered(_fails_on_three, list(range(200)), jobs=2)
    assert time.monotonic() - t0 < 30  # the queued tasks were cancelled, not all run


KILLS_ITS_WORKER = textwrap.dedent(
    """
    import os, signal, sys
    from pressor.plumbing.parallel import WorkerLost, run_ordered

    def task(x):
        if x == 2:
            os.kill(os.getpid(), signal.SIGKILL)  # as the out-of-memory killer would
        return x

    if __name__ == "__main__":
        try:
            run_ordered(task, list(range(6)), jobs=2)
        except WorkerLost as exc:
            print(exc)
            sys.exit(3)
        sys.exit(0)
    """
)


def test_a_killed_worker_is_an_error_naming_what_was_left_not_a_hang(tmp_path):
    script = tmp_path / "kills.py"
    script.write_text(KILLS_ITS_WORKER)
    # a multiprocessing.Pool waits forever here: the timeout turns such a hang into a failure
    proc = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=120, check=False
    )
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert "a worker process ended abruptly" in proc.stdout
    assert "of 6 tasks unfinished" in proc.stdout
