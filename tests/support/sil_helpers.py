"""Shared helpers for end-to-end tests: run the ``pressor`` CLI in a subprocess, read a .rrd,
spawn ``pressor device`` on a pty and drain its link until it exits, bridge two ttys."""

from __future__ import annotations

import os
import select
import subprocess
import sys
import threading
import time
import tty
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

os.environ["CI"] = "1"  # the rerun CLI writes analytics files otherwise

import numpy as np  # noqa: E402
from rerun.chunk import RrdReader  # noqa: E402

from pressor.link import LinkClosedError, PtyPair, RuntimeSession  # noqa: E402
from pressor.runtime.inputs.config import RunConfig  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def lockstep_run_config(controller: str, schedule: str) -> RunConfig:
    """A lockstep ``pressor run`` configuration with no output files (``run_runtime`` tests)."""
    return RunConfig(
        controller=controller,
        rate_hz=10.0,
        realtime=False,
        rrd=None,
        tlog=None,
        summary=None,
        timing=None,
        signing_key=None,
        sched_faults="advise",
        faults=(),
        fault_specs=(),
        stall_timeout_s=20.0,
        cpu_latency_us=None,
        schedule=schedule,
    )


def pressor(*args: str, cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess:
    """Run ``python -m pressor ARGS`` in ``cwd`` and capture its output."""
    return subprocess.run(
        [sys.executable, "-m", "pressor", *args],
        cwd=cwd,
        env=dict(os.environ, CI="1"),
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def rrd_columns(path: Path) -> dict[str, dict[int, float]]:
    """Every scalar series in a recording: entity path -> {tick: value}."""
    out: dict[str, dict[int, float]] = {}
    for chunk in RrdReader(str(path)).stream().to_chunks():
        batch = chunk.to_record_batch()
        if "tick" not in batch.schema.names or "Scalars:scalars" not in batch.schema.names:
            continue
        ticks = batch.column("tick").to_pylist()
        vals = [v[0] for v in batch.column("Scalars:scalars").to_pylist()]
        out.setdefault(str(chunk.entity_path), {}).update(zip(ticks, vals, strict=True))
    return out


def assert_recording_equals_simulation(rrd: Path, ref) -> np.ndarray:
    """Every tick of a SIL recording has the in-process simulation's MAP and command, bit for bit.

    ``ref`` is a :class:`pressor.hil_sim.episode.Trajectory`; returns the recorded commands (ml/h).
    """
    cols = rrd_columns(rrd)
    n = ref.t_s.size
    assert sorted(cols["/pump/command_ml_h"]) == list(range(n))
    sil_map = np.array([cols["/patient/map_mmhg"][k] for k in range(n)])
    sil_cmd = np.array([cols["/pump/command_ml_h"][k] for k in range(n)], dtype=np.float32)
    np.testing.assert_array_equal(sil_map, ref.map_mmhg)
    np.testing.assert_array_equal(sil_cmd.astype(np.float64), ref.command_ml_h)
    return sil_cmd


def spawn_device(pair: PtyPair, *args: str) -> subprocess.Popen:
    """Start ``pressor device`` on the pty's follower end; its stderr is piped as text.

    Unsigned (``--no-signing``) unless ``args`` give a ``--signing-key``.
    """
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "pressor", "device", "--port", pair.follower_path, *args]
    if "--signing-key" not in args:
        cmd.append("--no-signing")
    return subprocess.Popen(cmd, cwd=ROOT, env=env, stderr=subprocess.PIPE, text=True)


def poll_until_exit(proc: subprocess.Popen, ep: RuntimeSession, timeout_s: float) -> None:
    """Keep reading the link until the device process exits, the link closes or time runs out."""
    deadline = time.monotonic() + timeout_s
    while proc.poll() is None and time.monotonic() < deadline:
        try:
            ep.poll(0.05)
        except LinkClosedError:
            break


def _pty() -> tuple[int, int, str]:
    leader, follower = os.openpty()
    tty.setraw(follower)
    return leader, follower, os.ttyname(follower)


@contextmanager
def bridged_ttys() -> Iterator[tuple[str, str]]:
    """Two tty paths whose bytes cross over, like a null-modem cable: each end opens the follower
    of its own pty and a thread copies bytes between the two leaders (what ``socat`` does)."""
    (la, fa, pa), (lb, fb, pb) = _pty(), _pty()
    stop = threading.Event()

    def bridge() -> None:
        while not stop.is_set():
            ready, _, _ = select.select([la, lb], [], [], 0.05)
            for fd in ready:
                try:
                    data = os.read(fd, 65536)
                except OSError:
                    continue
                os.write(lb if fd == la else la, data)

    thread = threading.Thread(target=bridge, daemon=True)
    thread.start()
    try:
        yield pa, pb
    finally:
        stop.set()
        thread.join()
        for fd in (la, fa, lb, fb):
            os.close(fd)
