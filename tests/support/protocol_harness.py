"""The runtime side of a protocol-device run: the signing key both ends read, and the wait until
``pressor run`` has opened its end of the pty.

Used by the protocol-device tests and by ``benchmarks/independent_patients.py``.
"""

from __future__ import annotations

import secrets
import select
import subprocess
import time
from pathlib import Path


def write_key(path: Path) -> Path:
    """A fresh signing key file as docs/PROTOCOL.md describes it: 64 hex characters, mode 0600."""
    path.write_text(secrets.token_hex(32) + "\n")
    path.chmod(0o600)
    return path


def wait_for_port_open(master: int, proc: subprocess.Popen, timeout_s: float = 60.0) -> None:
    """Block until ``pressor run`` opened the pty's slave (the master stops reporting hang-up)."""
    poller = select.poll()
    poller.register(master, select.POLLIN)
    deadline = time.monotonic() + timeout_s
    while any(ev & select.POLLHUP for _, ev in poller.poll(0)):
        assert proc.poll() is None, "pressor run exited before opening its port"
        assert time.monotonic() < deadline, "pressor run did not open its port"
        time.sleep(0.01)
