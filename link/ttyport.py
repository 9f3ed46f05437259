"""Ports over tty descriptors: pty pairs and the hot path of a posix serial port.

Facts this module relies on:

- A pty in cooked mode mangles bytes (CR/LF translation, echo, ^C...); both sides are put in raw
  mode at once, before anyone writes.
- A pty ignores the baud rate; link timing, if needed, is modelled in virtual time.

Hot path (lockstep runs trade a frame burst per tick each way, so per-read overhead is the run's
cost): ports over a tty descriptor - :class:`FdPort` and :func:`fast_port` around a posix pyserial
port - offer ``read_some(timeout_s)``, which returns everything available in one ``os.read``. On a
follower (a real tty device) it waits for the first byte with the tty's own timer (``VMIN=0,
VTIME=1``: one blocking syscall, no ``select``, no ``FIONREAD`` ioctl) when the wait is at least
:data:`VTIME_S`; shorter waits, and the pty leader (whose termios calls act on the follower, so it
has no timer of its own), use one ``select`` first. A ``FIONREAD`` right after the peer's write
waits for the kernel's flip-buffer work, a blocking read does not, and pyserial's ``read`` adds
Python per call (figures: docs/notes/benchmarks.md, "Design measurements").
"""

from __future__ import annotations

import errno
import fcntl
import os
import select
import struct
import termios
import tty
from dataclasses import dataclass, field
from typing import Any

import serial

from pressor.link.ports import DEFAULT_READ_TIMEOUT_S, PortWrapper, open_port

#: The tty read timer of fast ports (s): ``VTIME`` is in tenths of a second; a ``read_some`` wait
#: at least this long is one blocking ``os.read`` that returns on the first byte or after this.
VTIME_S = 0.1

#: Bytes taken per ``os.read`` (a lockstep tick is ~200 B; a stall may leave a few kB queued).
READ_CHUNK = 1 << 16


class FdPort:
    """A pyserial-like port over a raw file descriptor (the leader side of a pty).

    Parameters
    ----------
    fd
        An open file descriptor; owned (closed by :meth:`close`).
    timeout_s
        Read timeout (s): ``read`` returns what is there after at most this long.
    """

    def __init__(self, fd: int, timeout_s: float = DEFAULT_READ_TIMEOUT_S) -> None:
        self.fd = fd
        self.timeout: float | None = timeout_s
        self.is_open = True
        self._buf = bytearray(4)

    def read_some(self, timeout_s: float) -> bytes:
        """Everything readable now, waiting at most ``timeout_s`` (s) for the first byte.

        One ``select`` and one ``os.read``: a pty leader reads with the driver's fixed settings
        (termios calls on it act on the follower), so it has no read timer. Returns ``b""`` on
        timeout. Raises
        :class:`serial.SerialException` when the peer closed the link.
        """
        if not self.is_open:
            raise serial.PortNotOpenError()
        return _read_some(self.fd, timeout_s, timer=False)

    @property
    def in_waiting(self) -> int:
        """Bytes readable without blocking."""
        fcntl.ioctl(self.fd, termios.FIONREAD, self._buf)
        return struct.unpack("i", self._buf)[0]

    def read(self, size: int = 1) -> bytes:
        """Read up to ``size`` bytes, waiting at most ``timeout`` for the first one.

        Returns ``b""`` on timeout. Raises :class:`serial.SerialException` (as pyserial does for a
        vanished device) when no process holds the follower open any more (EIO on a pty leader).
        """
        if not self.is_open:
            raise serial.PortNotOpenError()
        ready, _, _ = select.select([self.fd], [], [], self.timeout)
        if not ready:
            return b""
        try:
            data = os.read(self.fd, size)
        except OSError as exc:
            if exc.errno == errno.EIO:  # follower closed by every process
                raise serial.SerialException(f"pty fd {self.fd}: peer closed the link") from exc
            raise
        if not data:
            raise serial.SerialException(f"pty fd {self.fd}: peer closed the link")
        return data

    def write(self, data: bytes) -> int:
        """Write all of ``data`` (blocking until the kernel took it)."""
        if not self.is_open:
            raise serial.PortNotOpenError()
        return _write_all(self.fd, data)

    def flush(self) -> None:
        """Nothing to flush: writes go straight to the kernel."""

    def reset_input_buffer(self) -> None:
        """Discard pending input."""
        termios.tcflush(self.fd, termios.TCIFLUSH)

    def close(self) -> None:
        """Close the descriptor (idempotent)."""
        if self.is_open:
            self.is_open = False
            os.close(self.fd)


def _set_read_timer(fd: int) -> None:
    """Make a blocking read on tty ``fd`` return on the first byte or after :data:`VTIME_S`."""
    attrs = termios.tcgetattr(fd)
    cc = attrs[6]
    vtime = max(1, round(VTIME_S * 10))
    if cc[termios.VMIN] != 0 or cc[termios.VTIME] != vtime:
        cc[termios.VMIN] = 0
        cc[termios.VTIME] = vtime
        termios.tcsetattr(fd, termios.TCSANOW, attrs)


def _closed(fd: int, exc: BaseException | None = None) -> serial.SerialException:
    err = serial.SerialException(f"tty fd {fd}: peer closed the link")
    if exc is not None:
        err.__cause__ = exc
    return err


def _read_some(fd: int, timeout_s: float, timer: bool = True) -> bytes:
    """Read what tty ``fd`` has, waiting up to ``timeout_s`` (s); ``timer``: ``fd`` reads with
    ``VMIN=0, VTIME`` set (:func:`_set_read_timer`), so a long wait needs no ``select``."""
    try:
        if timer and timeout_s >= VTIME_S:
            data = os.read(fd, READ_CHUNK)  # one syscall: returns on the first byte or VTIME
            if data:
                return data
            # nothing within VTIME, or a hang-up (which also reads empty): tell them apart
            if not select.select([fd], [], [], 0)[0]:
                return b""
        elif not select.select([fd], [], [], max(0.0, timeout_s))[0]:
            return b""
        data = os.read(fd, READ_CHUNK)
    except OSError as exc:
        if exc.errno == errno.EIO:  # pty: the other side is closed by every process
            raise _closed(fd, exc) from exc
        raise
    if not data:  # readable yet empty: end of file
        raise _closed(fd)
    return data


def _write_all(fd: int, data: bytes) -> int:
    n = os.write(fd, data)
    if n == len(data):
        return n
    view = memoryview(data)
    while n < len(view):
        n += os.write(fd, view[n:])
    return n


class FastPort(PortWrapper):
    """A posix pyserial port whose hot path bypasses pyserial's Python wrapper.

    pyserial opened and configured the device (what a user with real hardware gets); reads and
    writes then go straight to its descriptor (see the module docstring, "Hot path"). Everything
    else (``in_waiting``, ``read``, ``close``, ``timeout``) is pyserial's.

    Parameters
    ----------
    port
        An open ``serial.Serial`` on a tty (see :func:`fast_port`).
    """

    def __init__(self, port: Any) -> None:
        self._port = port
        self.fd: int = port.fd
        # pyserial opens O_NONBLOCK and waits in select; the read timer needs a blocking read
        os.set_blocking(self.fd, True)
        _set_read_timer(self.fd)

    @property
    def is_open(self) -> bool:
        return bool(self._port.is_open)

    def read_some(self, timeout_s: float) -> bytes:
        """Everything readable now, waiting at most ``timeout_s`` (s) for the first byte.

        Returns ``b""`` on timeout (a wait of at least :data:`VTIME_S` may return after
        :data:`VTIME_S`: callers loop on their own deadline). Raises
        :class:`serial.SerialException` when the peer closed the link.
        """
        if not self._port.is_open:
            raise serial.PortNotOpenError()
        return _read_some(self.fd, timeout_s)

    def write(self, data: bytes) -> int:
        """Write all of ``data`` to the descriptor."""
        if not self._port.is_open:
            raise serial.PortNotOpenError()
        return _write_all(self.fd, data)

    def flush(self) -> None:
        """Nothing to flush: writes go straight to the kernel."""

    def reset_input_buffer(self) -> None:
        self._port.reset_input_buffer()


def fast_port(port: Any) -> Any:
    """``port`` with the tty hot path (:class:`FastPort`) if it is a posix pyserial port on a tty;
    otherwise ``port`` unchanged (``loop://``, ``socket://``, non-posix platforms)."""
    fd = getattr(port, "fd", None)
    if isinstance(port, serial.Serial) and isinstance(fd, int) and fd >= 0:
        try:
            if os.isatty(fd):
                return FastPort(port)
        except OSError:
            pass
    return port


@dataclass
class PtyPair:
    """A pseudo-terminal pair, both sides in raw mode from the start.

    The leader side stays in this process as an :class:`FdPort` (:meth:`leader_port`); the follower
    is a real tty device at :attr:`follower_path` that another process (or thread) opens with
    pyserial. The pair keeps its own follower descriptor open until :meth:`close_follower` so that
    (a) the raw settings persist while the peer is starting and (b) reads on the leader do not fail
    with EIO before the peer has opened the follower.

    Attributes
    ----------
    leader_fd, follower_fd
        The two descriptors from ``os.openpty``.
    follower_path
        Device path of the follower (``/dev/pts/N``).
    """

    leader_fd: int
    follower_fd: int
    follower_path: str
    _leader_taken: bool = field(default=False, repr=False)
    _follower_closed: bool = field(default=False, repr=False)

    @classmethod
    def open(cls) -> PtyPair:
        """Create the pair and put both sides in raw mode at once."""
        leader, follower = os.openpty()
        for fd in (leader, follower):
            tty.setraw(fd, termios.TCSANOW)
        return cls(leader, follower, os.ttyname(follower))

    def leader_port(self, timeout_s: float = DEFAULT_READ_TIMEOUT_S) -> FdPort:
        """The leader side as a port (ownership of the descriptor moves to the port)."""
        self._leader_taken = True
        return FdPort(self.leader_fd, timeout_s)

    def follower_port(self, timeout_s: float = DEFAULT_READ_TIMEOUT_S):
        """Open the follower by path with pyserial (what a separate process does)."""
        return open_port(self.follower_path, timeout_s=timeout_s)

    def close_follower(self) -> None:
        """Drop this process's follower descriptor (after the peer has opened it)."""
        if not self._follower_closed:
            self._follower_closed = True
            os.close(self.follower_fd)

    def close(self) -> None:
        """Close what this object still owns."""
        self.close_follower()
        if not self._leader_taken:
            self._leader_taken = True
            os.close(self.leader_fd)
