"""Test doubles for the link: in-process crossed ``loop://`` ports, a write-fault port, and a
complete tick as the world would build it.

Not shipped: the device's own link fault injection is :class:`pressor.hil_sim.scenarios.faults.LinkFaultPort`.
"""

from __future__ import annotations

import random
from typing import Any

import serial

from pressor.link.messages import TickInputs
from pressor.link.ports import DEFAULT_READ_TIMEOUT_S, PortWrapper
from pressor.link.session import Session


class CrossedPort(PortWrapper):
    """One end of an in-process link built from two pyserial ``loop://`` ports.

    A ``loop://`` port reads back what is written to it; crossing two of them gives a full-duplex
    pair: this end writes into the peer's loop and reads its own; closing it closes its own loop
    (the peer then reads nothing more).
    """

    def __init__(self, own: serial.SerialBase, peer: serial.SerialBase) -> None:
        self._port = own
        self._peer = peer

    def write(self, data: bytes) -> int | None:
        return self._peer.write(data)

    def flush(self) -> None:
        """Nothing buffered on this side."""


def loop_pair(
    timeout_s: float = DEFAULT_READ_TIMEOUT_S, buffer_size: int = 1 << 16
) -> tuple[CrossedPort, CrossedPort]:
    """Two connected in-process ports over pyserial ``loop://`` (tests).

    Parameters
    ----------
    timeout_s
        Read timeout (s) of both ends.
    buffer_size
        Bytes each direction holds before a writer blocks (use a reader thread per end).
    """
    a = serial.serial_for_url("loop://", timeout=timeout_s, do_not_open=True)
    b = serial.serial_for_url("loop://", timeout=timeout_s, do_not_open=True)
    for p in (a, b):
        p.buffer_size = buffer_size
        p.open()
    return CrossedPort(a, b), CrossedPort(b, a)


class FaultyPort(PortWrapper):
    """Fault injection on the write path of a port: corrupt or drop whole writes deterministically.

    Every ``corrupt_every``-th write has one byte flipped (position chosen by a seeded generator,
    XOR with a non-zero mask); every ``drop_every``-th write is discarded. Writes are frames or
    bursts of frames as the session emits them, so "every N frames" holds when the session flushes
    per frame. 0 disables a fault.

    Parameters
    ----------
    port
        The port to wrap.
    corrupt_every, drop_every
        Period (writes) of each fault; 0 = never.
    seed
        Seed of the byte-position generator.
    """

    def __init__(
        self, port: Any, *, corrupt_every: int = 0, drop_every: int = 0, seed: int = 0
    ) -> None:
        if corrupt_every < 0 or drop_every < 0:
            raise ValueError("corrupt_every and drop_every must be >= 0")
        self._port = port
        self.corrupt_every = corrupt_every
        self.drop_every = drop_every
        self._rng = random.Random(seed)
        self.writes = 0
        self.corrupted = 0
        self.dropped = 0

    def write(self, data: bytes) -> int | None:
        self.writes += 1
        if self.drop_every and self.writes % self.drop_every == 0:
            self.dropped += 1
            return len(data)
        if self.corrupt_every and self.writes % self.corrupt_every == 0 and data:
            buf = bytearray(data)
            buf[self._rng.randrange(len(buf))] ^= self._rng.randrange(1, 256)
            self.corrupted += 1
            data = bytes(buf)
        return self._port.write(data)

    def flush(self) -> None:
        flush = getattr(self._port, "flush", None)
        if flush is not None:
            flush()


def tick_inputs(
    k: int,
    sim_time_s: float,
    map_mmhg: float,
    quality: int = 0,
    target_mmhg: float = 90.0,
    K: float = 0.5,
    T_s: float = 150.0,
    tau_s: float = 30.0,
    sched_valid: bool = True,
) -> TickInputs:
    """Tick ``k``'s inputs with scheduling parameters and target of the same tick (as the world
    builds them): MAP (mmHg), target (mmHg), K (mmHg/(ml/h)), T and tau (s)."""
    return TickInputs(
        k, sim_time_s, map_mmhg, quality, target_mmhg, K, T_s, tau_s, sched_valid, k, k
    )


class SinkPort:
    """A port that keeps what is written (no reads): frames as the session emits them."""

    timeout = 0.01
    in_waiting = 0

    def __init__(self) -> None:
        self.data = bytearray()

    def write(self, data: bytes) -> int:
        self.data += data
        return len(data)

    def read(self, size: int = 1) -> bytes:
        return b""

    def close(self) -> None:
        pass


def collect(ep: Session) -> list:
    """The message objects ``ep`` accepts from now on (a list that fills as it reads)."""
    got: list = []
    ep.on_message = got.append
    return got


def drain(ep: Session, quiet_s: float = 0.05) -> None:
    """Read until nothing arrives for ``quiet_s`` (s)."""
    while ep.poll(quiet_s):
        pass
