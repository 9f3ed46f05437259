"""Hold a CPU wake-up latency request (Linux PM QoS, ``/dev/cpu_dma_latency``) during a run.

Why. Every lockstep tick crosses the pty twice, and each crossing wakes a task that was sleeping
(the pty's flush worker, then the reader). On a host whose idle CPUs halt (a VM guest with
halt-polling off, or a laptop in a deep C-state), waking a halted CPU costs tens of µs per hop
(figures: docs/notes/benchmarks.md, "Design measurements"; ``benchmarks/sil.py`` prints both
ways). Real-time
control stacks do the same (cyclictest, EtherCAT masters, ros2_control's realtime guides): while
the file descriptor is open the kernel keeps every CPU out of idle states slower than the
request; closing it (or the process ending) withdraws the request.

The request is best effort: writing the device usually needs root. When it cannot be made the run
goes on and :attr:`CpuLatencyRequest.status` says why.
"""

from __future__ import annotations

import os
import struct

from pressor.contracts.checks import check_int_range

#: the PM QoS device of the CPU wake-up latency (µs, a native int32)
QOS_DEVICE = "/dev/cpu_dma_latency"
#: largest request accepted (µs); the kernel's own default is 2e9
MAX_LATENCY_US = 1_000_000


class CpuLatencyRequest:
    """Context manager holding ``/dev/cpu_dma_latency`` at ``latency_us`` inside the block.

    Parameters
    ----------
    latency_us
        Largest acceptable CPU wake-up latency (µs, 0 … :data:`MAX_LATENCY_US`); 0 keeps CPUs
        polling instead of halting when idle. ``None`` makes no request.
    device
        The PM QoS device (tests point it elsewhere).

    Attributes
    ----------
    held
        True while the request is in force.
    status
        One line for the run's report: what was requested, or why nothing was.
    """

    def __init__(self, latency_us: int | None, device: str = QOS_DEVICE) -> None:
        if latency_us is not None:
            check_int_range("cpu wake-up latency", latency_us, 0, MAX_LATENCY_US, unit="µs")
        self.latency_us = latency_us
        self.device = device
        self.held = False
        self.status = "off (not requested)"
        self._fd: int | None = None

    def __enter__(self) -> CpuLatencyRequest:
        if self.latency_us is None:
            return self
        try:
            fd = os.open(self.device, os.O_WRONLY | os.O_CLOEXEC)
        except OSError as exc:
            self.status = f"not held: cannot open {self.device} ({exc.strerror})"
            return self
        try:
            os.write(fd, struct.pack("=i", self.latency_us))
        except OSError as exc:
            os.close(fd)
            self.status = f"not held: cannot write {self.device} ({exc.strerror})"
            return self
        self._fd = fd
        self.held = True
        self.status = f"held at {self.latency_us} us ({self.device})"
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def release(self) -> None:
        """Withdraw the request (idempotent)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
            self.held = False
