"""MAVLink telemetry log (.tlog) writer and reader.

The standard layout (QGroundControl, MAVProxy, pymavlink's ``mavutil``): each raw MAVLink frame is
preceded by an 8-byte big-endian timestamp in microseconds. Deviation from the usual practice:
the timestamp is the *run's* clock (device sim time in lockstep, seconds since start in real-time
mode), not the Unix wall clock, so two runs with the same seed give byte-identical logs. Tools that
print dates will show 1970.

Only frames that decoded (sent by this end, or received and accepted) are logged: a corrupted
frame in a .tlog would desynchronise readers that trust the timestamp/frame layout. The session's
counters record what was rejected.

Stock ``mavlogdump.py`` reads a log with the dialect XML under ``link/message_definitions/v1.0``
(links to ``link/pressor.xml`` and ``link/minimal.xml``), from the project root::

    MAVLINK20=1 MDEF=link/message_definitions mavlogdump.py --dialect pressor run.tlog

In Python, make the committed dialect module known to pymavlink's tools first::

    from pressor.link.tlog import register_dialect_with_mavutil
    mavutil = register_dialect_with_mavutil()
    log = mavutil.mavlink_connection("run.tlog", dialect="pressor")
"""

from __future__ import annotations

import os
import struct
import threading
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

_TS = struct.Struct(">Q")
_ZERO_TS = _TS.pack(0)


class TlogWriter:
    """Append frames to a .tlog file, written in place, durable within a second, never raising.

    The record of a run that went wrong is the one an investigator needs most, so the log is
    written at ``path`` itself from the start (not through a temporary name): a run that fails,
    is refused or is killed leaves the log of everything up to its end.

    Off the control path: :meth:`write` only appends to a memory buffer (no system call); a
    writer thread moves the buffer to the file and makes it durable (``fsync``) every
    ``flush_every_s`` seconds, and :meth:`close` does so a last time. A SIGKILL therefore loses at
    most the last ``flush_every_s`` (a truncated last frame is skipped by :func:`read_tlog` and by
    ``mavlogdump.py``).

    A disk that fills up or fails never reaches the caller: the first ``OSError`` stops the log
    there (what was written stays readable), :attr:`error` names the file and the cause, and
    later frames are counted in :attr:`dropped`; the runtime raises its advisory
    ``RECORD_ERROR`` on it while control goes on. A buffer that outgrows ``max_buffer_bytes``
    (a writer stuck on a hung disk) is dropped the same way, so memory stays bounded.

    Parameters
    ----------
    path
        Output file (created or truncated at once).
    flush_every_s
        Longest time (s, wall clock) a written frame waits before it is durable; in (0, 1].
    max_buffer_bytes
        Largest backlog (bytes) kept in memory for a writer that cannot keep up.
    """

    def __init__(
        self,
        path: str | Path,
        flush_every_s: float = 0.5,
        max_buffer_bytes: int = 16 << 20,
    ) -> None:
        if not 0.0 < flush_every_s <= 1.0:
            raise ValueError(f"flush_every_s={flush_every_s!r}: allowed (0, 1] s")
        self.path = Path(path)
        self._fd: int | None = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._buf = bytearray()
        self._lock = threading.Lock()
        self._max = int(max_buffer_bytes)
        self._stop = threading.Event()
        #: frames logged (buffered or written)
        self.frames = 0
        #: frames not logged after the writer failed
        self.dropped = 0
        #: why the log stopped (names the file and the OS error), else ``None``
        self.error: str | None = None
        self._thread = threading.Thread(
            target=self._run, args=(flush_every_s,), name=f"tlog {self.path.name}", daemon=True
        )
        self._thread.start()

    def write(self, frame: bytes | bytearray, time_s: float) -> None:
        """Log one raw frame at run time ``time_s`` (s; outside [0, 2^63 µs) or not finite: 0)."""
        if self.error is not None:
            self.dropped += 1
            return
        us = time_s * 1e6
        stamp = _TS.pack(round(us)) if 0.0 < us < 9.2e18 else _ZERO_TS  # False for NaN too
        with self._lock:
            if len(self._buf) > self._max:
                self._fail(f"{self.path}: the disk does not keep up ({self._max} bytes behind)")
                self.dropped += 1
                return
            self._buf += stamp
            self._buf += frame
        self.frames += 1

    def _run(self, every_s: float) -> None:
        while not self._stop.wait(every_s):
            self._drain(durable=True)

    def _drain(self, *, durable: bool) -> None:
        """Write the buffer to the file (and ``fsync`` it when ``durable``); never raises."""
        with self._lock:
            data, self._buf = self._buf, bytearray()
        fd = self._fd
        if fd is None or self.error is not None:
            return
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
            if durable:
                os.fsync(fd)
        except OSError as exc:
            self._fail(f"{self.path}: {exc.strerror or exc}")

    def _fail(self, why: str) -> None:
        if self.error is None:
            self.error = why

    def flush(self) -> None:
        """Write buffered frames to the file now (made durable by the writer thread)."""
        self._drain(durable=False)

    def close(self, commit: bool = True) -> None:
        """Stop the writer thread, write the rest and make it durable, close (idempotent).

        ``commit`` is kept for callers of the atomic writer this replaced: the log stays in place
        either way (a failed run keeps its record).
        """
        if self._fd is None:
            return
        self._stop.set()
        self._thread.join()
        self._drain(durable=True)
        fd, self._fd = self._fd, None
        try:
            os.close(fd)
        except OSError as exc:
            self._fail(f"{self.path}: {exc.strerror or exc}")

    def __enter__(self) -> TlogWriter:
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        self.close()


def read_tlog(path: str | Path) -> Iterator[tuple[int, bytes]]:
    """Yield ``(timestamp_us, raw_frame)`` from a .tlog written by :class:`TlogWriter`.

    Frames are delimited by their MAVLink 2 header (length byte, signed flag); a truncated tail is
    ignored.
    """
    data = Path(path).read_bytes()
    i, n = 0, len(data)
    while i + 8 + 10 <= n:
        (us,) = _TS.unpack_from(data, i)
        j = i + 8
        if data[j] != 0xFD:
            raise ValueError(f"{path}: no MAVLink 2 frame at byte {j}")
        length = 12 + data[j + 1] + (13 if data[j + 2] & 0x01 else 0)
        if j + length > n:
            return
        yield us, data[j : j + length]
        i = j + length


def register_dialect_with_mavutil() -> ModuleType:
    """Make ``dialect="pressor"`` work in pymavlink's ``mavutil`` and return ``mavutil``.

    ``mavutil.set_dialect`` imports ``pymavlink.dialects.v20.<name>``; this registers the committed
    module under that name (without writing into site-packages) and selects MAVLink 2.
    """
    import sys

    from pressor.link.dialect import pressor

    os.environ["MAVLINK20"] = "1"
    sys.modules["pymavlink.dialects.v20.pressor"] = pressor
    import pymavlink.dialects.v20 as v20

    v20.pressor = pressor  # type: ignore[attr-defined]
    from pymavlink import mavutil

    mavutil.set_dialect("pressor")
    return mavutil
