"""Memory soak of ``pressor run``'s code path: does the runtime grow with the length of a run?

Runs one lockstep case through :func:`pressor.sil.run_sil` (the device as its own process on a
pty, the runtime in this process through :func:`pressor.runtime.session.run_runtime`, the same
loop, supervisor, schedule and kept trajectory as ``pressor run``; no recording, as ``pressor
run`` without ``--rrd``) and measures this process's memory from the run itself: Python's traced
allocations (:mod:`tracemalloc`: every Python object and numpy array the runtime holds) and the
resident set size (RSS, from /proc), at the baseline tick (``--baseline-min`` of simulated time,
once the start-up has settled) and at the last tick, before the run's result is assembled.
Prints both growths in MB per simulated hour, and the kept trajectory's own size
(:attr:`pressor.runtime.shell.trajectory.Trajectory.nbytes`) per hour.

Usage::

    python -m benchmarks.memory_soak                       # 2 h, lpv on the estimated schedule
    python -m benchmarks.memory_soak --hours 6 --controller pi --schedule oracle

Exit 1 if the traced growth exceeds ``--max-growth-mb-h`` (default 1 MB per simulated hour, the
bound of docs/PROTOCOL.md).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import tracemalloc
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("CI", "1")  # before rerun is imported: no analytics files

from pressor.sil import run_sil, sil_config  # noqa: E402


def rss_mb() -> float:
    """Resident set size (MB) of this process, from /proc."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--hours", type=float, default=2.0, help="simulated time (h), default 2")
    p.add_argument("--controller", default="lpv", help="as pressor run's (default lpv)")
    p.add_argument("--schedule", default="estimated", help="as pressor run's (default estimated)")
    p.add_argument("--baseline-min", type=float, default=10.0, help="baseline tick (sim min)")
    p.add_argument("--max-growth-mb-h", type=float, default=1.0)
    args = p.parse_args(argv)
    if not args.baseline_min * 60.0 < args.hours * 3600.0 <= 7 * 86400.0:
        print(f"--hours {args.hours}: allowed (--baseline-min, 168]", file=sys.stderr)
        return 2
    config = sil_config(
        ["--controller", args.controller, "--schedule", args.schedule,
         "--duration", repr(args.hours * 3600.0), "--cpu", "none"]
    )  # fmt: skip
    config = replace(config, run=replace(config.run, rrd=None))  # pressor run without --rrd
    period_s = config.run.period_s
    base_tick = round(args.baseline_min * 60.0 / period_s)
    last_tick = round(config.duration_s / period_s) - 1
    marks: dict[str, tuple[int, float, float]] = {}

    def probe(tick: int, _state: int, _faults: int, _command: float) -> None:
        if tick == base_tick or tick == last_tick:
            marks["base" if tick == base_tick else "end"] = (
                tick,
                tracemalloc.get_traced_memory()[0] / 1e6,
                rss_mb(),
            )

    tracemalloc.start()
    wall = time.perf_counter()
    summary, result = run_sil(config, on_tick=probe)
    wall = time.perf_counter() - wall
    tracemalloc.stop()
    if "end" not in marks:
        print(f"the run ended early ({result.ended}): no growth measured", file=sys.stderr)
        return 1
    (t0, traced0, rss0), (t1, traced1, rss1) = marks["base"], marks["end"]
    hours = (t1 - t0) * period_s / 3600.0
    traced_mb_h = (traced1 - traced0) / hours
    rss_mb_h = (rss1 - rss0) / hours
    kept_bytes = getattr(result, "kept_bytes", None)  # the Trajectory's own size, when known
    if kept_bytes is None:  # the columns the run returned
        kept_bytes = sum(a.nbytes for a in result.trajectory.values())
    kept = kept_bytes / 1e6
    print(
        f"memory soak: {args.hours:g} h simulated ({t1 + 1} ticks), controller {args.controller},"
        f" schedule {args.schedule}, {wall:.1f} s wall; ended: {result.ended}"
    )
    print(
        f"traced (tracemalloc): {traced0:.2f} MB at {t0 * period_s / 60:g} min, {traced1:.2f} MB"
        f" at the end: growth {traced_mb_h:+.3f} MB/h"
    )
    print(f"RSS: {rss0:.1f} MB -> {rss1:.1f} MB: growth {rss_mb_h:+.3f} MB/h")
    print(f"kept trajectory: {kept:.3f} MB, {kept / (t1 + 1) / period_s * 3600:.3f} MB/h")
    return 0 if traced_mb_h <= args.max_growth_mb_h else 1


if __name__ == "__main__":
    sys.exit(main())
