"""SIL benchmark: lockstep real-time factor over the pty, and wall-clock lateness at 10 Hz.

Runs ``pressor sil`` (device process + runtime over a pty, signed link, .rrd recording on) and
prints:

1. lockstep: simulated seconds per wall second (real-time factor) for ``--sim-hours`` of patient
   time (default 1 h) at 10 Hz — target ≥ 500× (1 h in ≤ 7.2 s). Two figures: the loop alone
   (first sample to last command) and the whole command (process start, handshake, recording
   written and renamed);
0. floor: a bare pty ping-pong between two processes (a 184-byte tick burst one way, a 33-byte
   command back; no Python work) on one CPU and across two, in the same run: the real-time
   factor no lockstep run over this pty on this machine can exceed;
2. real time: release lateness and execution time p50/p99/max at 10 Hz over ``--realtime-s``
   seconds of wall time (default 600 = 10 min; ``--quick``: 30 s) — target p99 ≤ 1 ms. This
   machine shows 10–20 ms host stalls whatever the sleep method (DESIGN.md §5): read the p99 with
   that in mind.

Usage: ``python benchmarks/sil.py [--quick] [--controller pi|lpv|PATH] [--sim-hours H]
[--realtime-s S]``.
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
    from runtime.cli import main

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


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="short runs (0.25 h lockstep, 30 s wall)")
    p.add_argument("--controller", default="pi")
    p.add_argument("--sim-hours", type=float, default=None)
    p.add_argument("--realtime-s", type=float, default=None)
    p.add_argument("--rate", type=float, default=10.0)
    p.add_argument("--cpu", default="auto", help="passed to pressor sil --cpu (auto|none|N)")
    a = p.parse_args(argv)
    sim_h = a.sim_hours if a.sim_hours is not None else (0.25 if a.quick else 1.0)
    rt_s = a.realtime_s if a.realtime_s is not None else (30.0 if a.quick else 600.0)
    n_floor = 3000
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    print(f"floor: bare pty ping-pong between two processes, {n_floor} round trips:")
    if len(cpus) >= 2:
        for label, pin in (("one CPU", (cpus[0], cpus[0])), ("two CPUs", (cpus[0], cpus[1]))):
            us = pty_floor_us(n_floor, pin)
            print(f"  {label:9s} {us:6.1f} us/round trip -> ceiling {1e6 / a.rate / us:.0f}x")
    us = pty_floor_us(n_floor, None)
    print(f"  unpinned  {us:6.1f} us/round trip -> ceiling {1e6 / a.rate / us:.0f}x")
    with tempfile.TemporaryDirectory(prefix="pressor-bench-") as tmp:
        d = Path(tmp)
        common = ["--controller", a.controller, "--rate", str(a.rate)]
        code, wall, text = _sil(
            [
                *common,
                "--duration",
                str(sim_h * 3600.0),
                "--cpu",
                a.cpu,
                "--rrd",
                str(d / "lockstep.rrd"),
                "--timing",
                str(d / "lockstep.json"),
            ]
        )
        if code != 0:
            print(text, file=sys.stderr)
            return code
        t = json.loads((d / "lockstep.json").read_text())
        rrd_mb = (d / "lockstep.rrd").stat().st_size / 1e6
        sim_s = t["sim_s"]
        print(
            f"lockstep over pty, {a.rate:g} Hz, signed, recording on ({a.controller},"
            f" --cpu {a.cpu}):"
        )
        print(f"  simulated {sim_s:.0f} s ({sim_h:g} h), {t['loop']['ticks']} ticks")
        print(
            f"  loop:          {t['run_wall_s']:.2f} s wall -> real-time factor"
            f" {sim_s / t['run_wall_s']:.0f}x   (target >= 500x)"
        )
        print(
            f"  whole command: {wall:.2f} s wall -> real-time factor {sim_s / wall:.0f}x"
            f"   (incl. device start, handshake, .rrd of {rrd_mb:.1f} MB written)"
        )
        lp = t["loop"]
        print(
            f"  runtime exec per tick p50/p99/max: {lp['exec_p50_us']:.1f} / {lp['exec_p99_us']:.1f}"
            f" / {lp['exec_max_us']:.1f} us"
        )
        code, wall, text = _sil(
            [
                *common,
                "--realtime",
                "--duration",
                str(rt_s),
                "--rrd",
                str(d / "realtime.rrd"),
                "--timing",
                str(d / "realtime.json"),
            ]
        )
        if code != 0:
            print(text, file=sys.stderr)
            return code
        lp = json.loads((d / "realtime.json").read_text())["loop"]
        print(f"real time (--realtime), {a.rate:g} Hz, {rt_s:g} s wall, {lp['ticks']} ticks:")
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


if __name__ == "__main__":
    sys.exit(main())
