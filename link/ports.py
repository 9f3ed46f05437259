"""Byte ports for the MAVLink link: the subset of pyserial the link uses, and opening one.

Everything here returns a *port*: an object with the small subset of the pyserial API the session
uses (``write(bytes)``, ``read(n)``, ``in_waiting``, ``close()``, ``timeout``). Real pyserial
objects satisfy it; :mod:`pressor.link.ttyport` adds ports over tty descriptors (pty pairs, the fast path).

Facts this package relies on:

- pyserial flushes its input when it opens a port, so a peer's bytes sent earlier are lost: the
  sessions handshake after both ends are open (repeated hellos, see ``Session.handshake``).
- ``port.read(port.in_waiting or 1)`` returns as soon as anything is there; ``read(n)`` would wait
  the whole timeout for n bytes. Changing ``timeout`` on an open posix port reconfigures the tty
  (tcsetattr) - it is set once, at open.
"""

from __future__ import annotations

from typing import Any, Protocol

import serial

#: Default read timeout (s): how long one blocking ``read`` may wait for the first byte. Wait loops
#: in the session re-check their own deadline after each read, so this only bounds overshoot.
DEFAULT_READ_TIMEOUT_S = 0.01


class Port(Protocol):
    """The subset of a pyserial port the link uses."""

    timeout: float | None

    def write(self, data: bytes, /) -> int | None: ...

    def read(self, size: int = 1, /) -> bytes: ...

    @property
    def in_waiting(self) -> int: ...

    def close(self) -> None: ...


class PortWrapper:
    """A port around another one (``self._port``): timeout, reads and close are the inner port's;
    subclasses change the write path."""

    _port: Any

    @property
    def timeout(self) -> float | None:
        return self._port.timeout

    @property
    def in_waiting(self) -> int:
        return self._port.in_waiting

    def read(self, size: int = 1) -> bytes:
        return self._port.read(size)

    def close(self) -> None:
        self._port.close()


def open_port(spec: str, *, timeout_s: float = DEFAULT_READ_TIMEOUT_S, baudrate: int = 115200):
    """Open a pyserial port from a URL (``loop://``, ``socket://host:port``, ...) or a device path.

    Parameters
    ----------
    spec
        A pyserial URL or a device path (``/dev/ttyUSB0``, ``/dev/pts/7``).
    timeout_s
        Read timeout (s) for one blocking read; set once here.
    baudrate
        Line rate for real UARTs (ignored by ptys and URLs without a line).

    Returns
    -------
    serial.SerialBase
        The open port.

    Raises
    ------
    serial.SerialException
        When the port cannot be opened (the message names ``spec``).
    """
    port = serial.serial_for_url(spec, baudrate=baudrate, timeout=timeout_s, write_timeout=None)
    return port
