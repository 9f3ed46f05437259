"""Live view benchmark: what ``--view`` costs a lockstep ``pressor sil`` run.

Runs ``pressor sil --duration S`` (lockstep, the default controller and scenario) ``--repeat``
times without and with ``--view`` (no display: rerun's web viewer, started once on a free port,
reused by every run, ended at the end) and prints, per variant, the median of the loop's wall
time (first sample to last command, ``--timing``'s ``run_wall_s``) and of the whole command's
(process start to exit: the viewer's start, the handshake, the recording written and, with
``--view``, its copy sent to the viewer).

Usage: ``python -m benchmarks.live_view [--duration S] [--repeat N]`` (default 3600 s, 3).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def free_port_pair() -> int:
    """A port P with P and P + 1 free on 127.0.0.1."""
    while True:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = int(s.getsockname()[1])
        with socket.socket() as s:
            if port < 65535 and s.connect_ex(("127.0.0.1", port + 1)) != 0:
                return port


def one_run(work: Path, duration_s: float, view_port: int | None) -> tuple[float, float, str]:
    """(loop wall s, command wall s, its stderr) of one ``pressor sil`` run."""
    timing = work / "t.json"
    cmd = [sys.executable, "-m", "pressor", "sil", "--duration", str(duration_s)]
    cmd += ["--rrd", str(work / "r.rrd"), "--timing", str(timing), "--quiet"]
    if view_port is not None:
        cmd += ["--view", "--view-port", str(view_port)]
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    started = time.perf_counter()
    proc = subprocess.run(cmd, cwd=work, env={**env, "CI": "1"}, capture_output=True, text=True)
    wall = time.perf_counter() - started
    if proc.returncode != 0:
        raise SystemExit(f"pressor sil exited {proc.returncode}: {proc.stderr.strip()}")
    return json.loads(timing.read_text())["run_wall_s"], wall, proc.stderr


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--duration", type=float, default=3600.0, help="simulated s per run")
    p.add_argument("--repeat", type=int, default=3, help="runs per variant")
    a = p.parse_args(argv)
    port = free_port_pair()
    viewer_pid = None
    try:
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            for label, view in (("without --view", None), ("with --view", port)):
                loops, walls = [], []
                for _ in range(a.repeat):
                    loop_s, wall_s, err = one_run(work, a.duration, view)
                    loops.append(loop_s)
                    walls.append(wall_s)
                    if view is not None and viewer_pid is None and "kill " in err:
                        viewer_pid = int(err.split("kill ")[1].split()[0])
                print(
                    f"{label:15s}  {a.duration:g} s simulated, median of {a.repeat}:"
                    f" loop {statistics.median(loops):.2f} s,"
                    f" command {statistics.median(walls):.2f} s"
                )
    finally:
        if viewer_pid is not None:
            os.kill(viewer_pid, signal.SIGTERM)
    return 0


if __name__ == "__main__":
    sys.exit(main())
