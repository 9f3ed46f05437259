"""CPU placement of the two lockstep ends: the runtime's loop thread and the device process.

``pressor sil --cpu auto|none|N|N,M`` chooses where the two ends run (:func:`parse_lockstep_cpus`,
:func:`lockstep_cpus`); the runtime pins its loop thread for the run (:class:`Pinned`) and the
device process pins itself on start (``pressor device --cpu N``, :func:`parse_cpu`,
:func:`pin_thread`). Both ends use this one module.

Why two CPUs. ``auto`` puts the two ends on two different CPUs: the loop thread stays on the CPU
it runs on and the device takes another. Each end then keeps its caches, and the runtime records
tick k while the device computes tick k+1 (recording happens after the command is sent). With the
CPU wake-up latency request held (:mod:`pressor.runtime.shell.cpu_latency`), two CPUs beat one (development
VM, LPV, 30 min at 10 Hz: 610-680x split, 620-650x unpinned, 460-470x on one CPU); without it split
and unpinned give ~400x and one CPU ~330x. ``benchmarks/sil.py`` measures the bare pty round trip
each way. Only the loop thread is pinned; the recorder's rerun threads stay free.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

#: a lockstep placement choice: ``auto``, ``none`` or ``(loop CPU, device CPU)``
CpuChoice = str | tuple[int, int]


def allowed_cpus() -> list[int]:
    """The CPUs this process may run on, sorted (empty where the OS cannot tell)."""
    return sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []


def parse_cpu(text: str) -> int:
    """An argparse type for ``pressor device --cpu N``: one CPU this process may run on."""
    allowed = allowed_cpus()
    try:
        cpu = int(text)
    except ValueError:
        cpu = -1
    if cpu not in allowed:
        raise argparse.ArgumentTypeError(f"--cpu {text!r}: allowed one of the CPUs {allowed}")
    return cpu


def parse_lockstep_cpus(text: str) -> CpuChoice:
    """An argparse type for ``pressor sil --cpu``: ``auto``, ``none``, ``N`` or ``N,M``.

    ``N`` is returned as ``(N, N)``; every number must be a CPU this process may run on.
    """
    if text in ("auto", "none"):
        return text
    allowed = allowed_cpus()
    hint = f"allowed auto, none, N or N,M with N and M in {allowed}"
    try:
        cpus = tuple(int(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--cpu {text!r}: {hint}") from None
    if len(cpus) not in (1, 2) or any(c not in allowed for c in cpus):
        raise argparse.ArgumentTypeError(f"--cpu {text!r}: {hint}")
    return (cpus[0], cpus[-1])


def lockstep_cpus(choice: CpuChoice, realtime: bool) -> tuple[int, int] | None:
    """``(loop CPU, device CPU)`` for a lockstep run, or ``None`` (no pinning).

    ``auto`` keeps the loop on the CPU this thread runs on and gives the device another (none
    when only one CPU is allowed); a real-time run and ``none`` are never pinned.
    """
    if choice == "none" or realtime or not hasattr(os, "sched_setaffinity"):
        return None
    if isinstance(choice, tuple):
        return choice
    allowed = os.sched_getaffinity(0)
    if len(allowed) < 2:
        return None
    here = current_cpu(allowed)
    return here, min(allowed - {here})


def current_cpu(allowed: set[int]) -> int:
    """The CPU this thread last ran on (``/proc/thread-self/stat`` field 39), else the lowest."""
    try:
        text = Path("/proc/thread-self/stat").read_text()
        cpu = int(text[text.rindex(")") + 2 :].split()[36])
        if cpu in allowed:
            return cpu
    except (OSError, ValueError, IndexError):
        pass
    return min(allowed)


def pin_thread(cpu: int | None) -> set[int] | None:
    """Run the calling thread (and the threads it starts later) on ``cpu`` only.

    Returns the previous CPU set to restore, or ``None`` when ``cpu`` is ``None`` (no change).
    """
    if cpu is None:
        return None
    saved = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {cpu})
    return saved


class Pinned:
    """Run the calling thread on ``cpu`` inside the block (``None``: no change)."""

    def __init__(self, cpu: int | None) -> None:
        self.cpu = cpu
        self._saved: set[int] | None = None

    def __enter__(self) -> None:
        self._saved = pin_thread(self.cpu)

    def __exit__(self, *exc: object) -> None:
        if self._saved is not None:
            os.sched_setaffinity(0, self._saved)
