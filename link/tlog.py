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
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import BinaryIO

from pressor.plumbing.files import AtomicFile

_TS = struct.Struct(">Q")


class TlogWriter:
    """Append frames to a .tlog file, written atomically.

    Frames go to a hidden temporary sibling; :meth:`close` renames it over ``path`` (``commit``) or
    deletes it, so a failed run never clobbers an earlier log.

    Parameters
    ----------
    path
        Output file (replaced on a committed close).
    buffer_bytes
        Write buffer size; the file is flushed when it fills and on :meth:`close`.
    """

    def __init__(self, path: str | Path, buffer_bytes: int = 1 << 16) -> None:
        self.path = Path(path)
        self._target = AtomicFile(self.path)
        self._file: BinaryIO = open(self._target.tmp, "wb", buffering=buffer_bytes)  # noqa: SIM115
        self.frames = 0

    def write(self, frame: bytes | bytearray, time_s: float) -> None:
        """Log one raw frame at run time ``time_s`` (s, >= 0)."""
        us = int(round(time_s * 1e6))
        self._file.write(_TS.pack(us if us > 0 else 0))
        self._file.write(frame)
        self.frames += 1

    def flush(self) -> None:
        """Push buffered frames to the temporary file."""
        self._file.flush()

    def close(self, commit: bool = True) -> None:
        """Flush and close; rename into place if ``commit`` else discard (idempotent)."""
        if self._file.closed:
            return
        self._file.close()
        if commit:
            self._target.commit()
        else:
            self._target.discard()

    def __enter__(self) -> TlogWriter:
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        self.close(commit=exc_type is None)


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
