"""SIL benchmark: lockstep real-time factor over the pty, and wall-clock lateness at 10 Hz.

Runs ``pressor sil`` (device process + runtime over a pty, signed link, .rrd recording on) and
prints, in this order:

1. floor: a bare pty ping-pong between two processes (a 184-byte tick burst one way, a 33-byte
   command back; no Python work) on one CPU, across two and unpinned, without and with the CPU
   wake-up latency request (:mod:`pressor.runtime.shell.cpu_latency`): the real-time factor no lockstep run
   over this pty on this machine can exceed;
2. lockstep: simulated seconds per wall second (real-time factor) for ``--sim-hours`` of patient
   time (default 1 h) at 10 Hz, per controller and scheduling source (``--schedule``: the device's
   values, the online estimator, ...), with the wake-up latency request held (``--cpu-latency
   hold``) and without it (``--cpu-latency off``, the default of ``pressor sil``) — target >= 500x
   (1 h in <= 7.2 s). Two figures: the loop alone (first sample to last
   command) and the whole command (process start, handshake, recording written and renamed);
3. real time: release lateness and execution time p50/p99/max at 10 Hz over ``--realtime-s``
   seconds of wall time (default 600 = 10 min; ``--quick``: 30 s; 0 skips it), first controller
   only — target p99 <= 1 ms. This machine shows 10-20 ms host stalls whatever the sleep method
   (docs/PLATFORM-NOTES.md): read the max with that in mind.

Usage: ``python -m benchmarks.sil [--quick] [--controller lpv,pi] [--schedule oracle,estimated]
[--sim-hours H] [--realtime-s S] [--cpu auto|none|N|N,M]``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("CI", "1")


def _sil(args: list[str]) -> tuple[int, float, str]:
    from pressor.sil import main

    out = io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out):
        code = main("sil", args)
    return code, time.perf_counter() - t0, out.getvalue()


_PONG_CHILD = """
import os, sys, tty
fd = os.open(sys.argv[1], os.O_RDWR | os.O_NOCTTY)
tty.setraw(fd)
out = b"x" * 184
for _ in range(int(sys.argv[2])):
    os.write(fd, out)
    got = 0
    while got < 33:
        got += len(os.read(fd, 4096))
"""


def pty_floor_us(n: int, cpus: tuple[int, int] | None) -> float:
    """Mean round trip (µs) of a bare two-process pty ping-pong; ``cpus``: (parent, child)."""
    import subprocess
    import termios
    import tty

    leader, follower = os.openpty()
    for fd in (leader, follower):
        tty.setraw(fd, termios.TCSANOW)
    saved = os.sched_getaffinity(0) if cpus else None
    prefix = ["taskset", "-c", str(cpus[1])] if cpus else []
    child = subprocess.Popen(
        [*prefix, sys.executable, "-c", _PONG_CHILD, os.ttyname(follower), str(n + 1)]
    )
    try:
        if cpus:
            os.sched_setaffinity(0, {cpus[0]})
        answer = b"y" * 33
        t0 = 0.0
        for i in range(n + 1):
            got = 0
            while got < 184:
                got += len(os.read(leader, 4096))
            if i == 0:
                t0 = time.perf_counter()  # child started and synchronised
            os.write(leader, answer)
        dt = time.perf_counter() - t0
        child.wait(10)
    finally:
        if saved is not None:
            os.sched_setaffinity(0, saved)
        os.close(leader)
        os.close(follower)
    return dt / n * 1e6


def print_floor(n: int, rate_hz: float) -> None:
    """The bare pty round trip per CPU placement, without and with the wake-latency request."""
    from pressor.runtime.shell.cpu_latency import CpuLatencyRequest

    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    placements: list[tuple[str, tuple[int, int] | None]] = [("unpinned", None)]
    if len(cpus) >= 2:
        placements = [("one CPU", (cpus[0], cpus[0])), ("two CPUs", (cpus[0], cpus[1]))]
        placements.append(("unpinned", None))
    print(f"floor: bare pty ping-pong between two processes, {n} round trips (us, ceiling x):")
    for latency in (None, 0):
        with CpuLatencyRequest(latency) as wake:
            figures = []
            for label, pin in placements:
                us = pty_floor_us(n, pin)
                figures.append(f"{label} {us:.1f} ({1e6 / rate_hz / us:.0f}x)")
            print(f"  cpu wake-up latency {wake.status}: " + ", ".join(figures))


def _timed_sil(d: Path, name: str, controller: str, rate: float, extra: list[str]):
    """``pressor sil`` with a recording and a timing file in ``d``; (timing, wall s, rrd MB) or
    ``None`` after printing the run's output when it failed."""
    rrd, timing = d / f"{name}.rrd", d / f"{name}.json"
    code, wall, text = _sil(
        [
            "--controller",
            controller,
            "--rate",
            str(rate),
            "--rrd",
            str(rrd),
            "--timing",
            str(timing),
        ]
        + extra
    )
    if code != 0:
        print(text, file=sys.stderr)
        return None
    return json.loads(timing.read_text()), wall, rrd.stat().st_size / 1e6


def lockstep(d: Path, controller: str, a: argparse.Namespace, latency: str, schedule: str) -> int:
    """One lockstep run over the pty with ``--schedule schedule``; print its real-time factors."""
    extra = ["--duration", str(a.sim_hours * 3600.0), "--cpu", a.cpu, "--cpu-latency", latency]
    extra += ["--schedule", schedule]
    run = _timed_sil(d, "lockstep", controller, a.rate, extra)
    if run is None:
        return 1
    t, wall, rrd_mb = run
    sim_s = t["sim_s"]
    lp = t["loop"]
    print(
        f"  {controller:3s} --schedule {schedule}, cpu wake-up latency"
        f" {t['host']['cpu_latency']}, cpus (loop, device)"
        f" {t['host']['cpus']}:"
    )
    print(
        f"    loop          {t['run_wall_s']:6.2f} s wall -> real-time factor"
        f" {sim_s / t['run_wall_s']:4.0f}x   (target >= 500x)"
    )
    print(
        f"    whole command {wall:6.2f} s wall -> real-time factor {sim_s / wall:4.0f}x"
        f"   (incl. device start, handshake, .rrd of {rrd_mb:.1f} MB written)"
    )
    print(
        f"    runtime exec per tick p50/p99/max: {lp['exec_p50_us']:.1f} / {lp['exec_p99_us']:.1f}"
        f" / {lp['exec_max_us']:.1f} us"
    )
    return 0


def realtime(d: Path, controller: str, a: argparse.Namespace) -> int:
    """One wall-clock run; print release lateness and execution time."""
    run = _timed_sil(
        d, "realtime", controller, a.rate, ["--realtime", "--duration", str(a.realtime_s)]
    )
    if run is None:
        return 1
    t = run[0]
    lp = t["loop"]
    print(
        f"real time (--realtime), {controller}, {a.rate:g} Hz, {a.realtime_s:g} s wall,"
        f" {lp['ticks']} ticks, cpu wake-up latency {t['host']['cpu_latency']}:"
    )
    print(
        f"  release lateness p50/p99/max: {lp['lateness_p50_us'] / 1e3:.3f} /"
        f" {lp['lateness_p99_us'] / 1e3:.3f} / {lp['lateness_max_us'] / 1e3:.3f} ms"
        "   (target p99 <= 1 ms)"
    )
    print(
        f"  exec p50/p99/max: {lp['exec_p50_us']:.1f} / {lp['exec_p99_us']:.1f} /"
        f" {lp['exec_max_us']:.1f} us; overruns {lp['overruns']};"
        f" skipped periods {lp['skipped_periods']}"
    )
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="short runs (0.25 h lockstep, 30 s wall)")
    p.add_argument(
        "--controller", default="lpv,pi", help="comma-separated: lpv, pi or generated .py files"
    )
    p.add_argument(
        "--schedule",
        default="oracle",
        help="comma-separated scheduling sources for the lockstep runs: oracle, estimated, nominal, validated",
    )
    p.add_argument("--sim-hours", type=float, default=None)
    p.add_argument("--realtime-s", type=float, default=None)
    p.add_argument("--rate", type=float, default=10.0)
    p.add_argument("--cpu", default="auto", help="passed to pressor sil --cpu (auto|none|N|N,M)")
    a = p.parse_args(argv)
    a.sim_hours = a.sim_hours if a.sim_hours is not None else (0.25 if a.quick else 1.0)
    a.realtime_s = a.realtime_s if a.realtime_s is not None else (30.0 if a.quick else 600.0)
    controllers = a.controller.split(",")
    print_floor(3000, a.rate)
    with tempfile.TemporaryDirectory(prefix="pressor-bench-") as tmp:
        d = Path(tmp)
        print(
            f"lockstep over pty, {a.rate:g} Hz, signed, recording on, {a.sim_hours:g} h"
            f" simulated ({round(a.sim_hours * 3600 * a.rate)} ticks), --cpu {a.cpu}:"
        )
        for latency in ("hold", "off"):
            for controller in controllers:
                for schedule in a.schedule.split(","):
                    if code := lockstep(d, controller, a, latency, schedule):
                        return code
        if a.realtime_s > 0:
            return realtime(d, controllers[0], a)
    return 0


if __name__ == "__main__":
    sys.exit(main())
