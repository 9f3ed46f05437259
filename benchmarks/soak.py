"""Soak: many hours of patient time in lockstep over the pty, with faults sprinkled in.

Starts ``pressor device`` as its own process on a pty (as ``pressor sil`` does) with a seeded
schedule of faults - every kind of the catalogue in turn, three per simulated hour - and runs the
runtime loop in this process with a bounded trajectory ring (the last hour) and a streaming fault
scorer, so nothing in the runtime grows with the run length. Prints the resident memory (RSS) of
the runtime and of the device at the start (after the first simulated minute) and at the end, the
real-time factor, and the fault table.

Usage::

    python -m benchmarks.soak                 # 24 h of patient time, PI controller
    python -m benchmarks.soak --hours 2 --controller lpv --rrd soak.rrd

Exit 1 if a command left [0, max] or the runtime's RSS grew by more than ``--max-growth-mb``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("CI", "1")  # before rerun is imported: no analytics files

from pressor.contracts.faults import FAULT_KINDS, FaultScorer, parse_faults  # noqa: E402
from pressor.link import Hello, PtyPair, RuntimeSession, Signing  # noqa: E402
from pressor.runtime.core.supervisor import Supervisor  # noqa: E402
from pressor.runtime.core.supervisor_config import (  # noqa: E402
    Fault,
    sched_limits_of,
    supervisor_config_for,
)
from pressor.runtime.inputs.controller_loader import load_controller  # noqa: E402
from pressor.runtime.shell.loop import Loop  # noqa: E402
from pressor.runtime.summary import print_fault_table  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def rss_mb(pid: int | str = "self") -> float:
    """Resident set size (MB) of a process, from /proc."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def schedule(hours: float, per_hour: int = 3) -> list[str]:
    """Fault texts: the catalogue's kinds in turn, ``per_hour`` per simulated hour, seeded."""
    out = []
    n = int(hours * per_hour)
    for i in range(n):
        kind = FAULT_KINDS[i % len(FAULT_KINDS)]
        start = 600.0 + i * 3600.0 / per_hour
        out.append(f"{kind}:start_s={start},seed={i}")
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--hours", type=float, default=24.0, help="patient time (h), default 24")
    p.add_argument("--controller", default="pi", help="pi (default), lpv or a generated .py")
    p.add_argument("--scenario", default="paper-tracking")
    p.add_argument("--patient-seed", type=int, default=1)
    p.add_argument("--rrd", type=Path, default=None, help="also record to this .rrd")
    p.add_argument("--max-growth-mb", type=float, default=5.0)
    args = p.parse_args()
    if not 0.0 < args.hours <= 24 * 7:
        print(f"--hours {args.hours}: allowed (0, 168]", file=sys.stderr)
        return 2
    ts = 0.1
    duration = args.hours * 3600.0
    texts = schedule(args.hours)
    specs = parse_faults(texts)
    controller = load_controller(args.controller, sample_period_s=ts)
    signing = Signing.generate()  # per-run key, wall-clock timestamps like the device's
    pair = PtyPair.open()
    with tempfile.TemporaryDirectory(prefix="pressor-soak-") as tmp:
        key = signing.write(Path(tmp) / "key")
        cmd = [sys.executable, "-m", "pressor", "device", "--port", pair.follower_path]
        cmd += ["--scenario", args.scenario, "--patient-seed", str(args.patient_seed)]
        cmd += ["--duration", repr(duration), "--signing-key", str(key), "--retransmit", "0.05"]
        cmd += ["--link-timeout", "60"]
        for t in texts:
            cmd += ["--fault", t]
        log = open(Path(tmp) / "device.log", "wb")  # noqa: SIM115
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
        ep = RuntimeSession(pair.leader_port(), signing=signing)
        recorder = None
        try:
            peer = ep.handshake(Hello(args.controller[:32]), timeout_s=60.0)
            pair.close_follower()
            sup = Supervisor(supervisor_config_for(controller, peer.sensor_noise_mmhg))
            scorer = FaultScorer(
                specs,
                {f.name: int(f) for f in Fault if f.name},
                ts,
                scheduled=sched_limits_of(controller)[0] is not None,
            )
            marks: dict[str, float] = {}
            start_tick = int(60.0 / ts)

            def on_tick(tick: int, state: int, faults: int, command: float) -> None:
                scorer.update(tick, state, faults, command)
                if tick == start_tick:
                    marks["rt0"] = rss_mb()
                    marks["dev0"] = rss_mb(proc.pid)
                    marks["wall0"] = time.perf_counter()

            if args.rrd is not None:
                from pressor.runtime.record.recorder import Recorder

                recorder = Recorder(args.rrd, run_label=f"soak|{args.controller}|{args.hours}h")
            loop = Loop(
                controller,
                sup,
                ep,
                recorder=recorder,
                history_ticks=36000,
                on_tick=on_tick,
            )
            wall = time.perf_counter()
            result = loop.run_lockstep(peer.n_ticks, stall_timeout_s=60.0)
            wall = time.perf_counter() - wall
            rt1, dev1 = rss_mb(), rss_mb(proc.pid)
            if recorder is not None:
                recorder.close()
                recorder = None
        finally:
            if recorder is not None:
                recorder.abort()
            ep.close()
            pair.close()
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.terminate()
                proc.wait()
            log.close()
    sim_s = peer.n_ticks * ts
    growth = rt1 - marks["rt0"]
    print(
        f"soak: {args.hours:g} h of patient time ({peer.n_ticks} ticks), controller"
        f" {args.controller}, {len(specs)} faults; ended: {result.ended}"
    )
    print(f"wall {wall:.1f} s -> real-time factor {sim_s / wall:.0f}x")
    print(
        f"RSS runtime: start {marks['rt0']:.1f} MB, end {rt1:.1f} MB (growth {growth:+.2f} MB);"
        f" device: start {marks['dev0']:.1f} MB, end {dev1:.1f} MB"
        f" (growth {dev1 - marks['dev0']:+.2f} MB)"
    )
    print(f"supervisor ticks in state: {result.ticks_in_state}")
    report = scorer.report()
    print_fault_table(report, result.commands_out_of_range)
    missed = [f["kind"] for f in report if f["applicable"] and f["within_bound"] is False]
    if missed:
        print(f"faults missed or late: {missed}")
    bad = result.commands_out_of_range > 0 or growth > args.max_growth_mb or bool(missed)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
