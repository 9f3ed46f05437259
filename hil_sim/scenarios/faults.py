"""Fault injection on the device side: the world (sensor, pump, scheduling) and the link.

The schedule is a list of :class:`pressor.contracts.faults.FaultSpec` (parsed from ``--fault KIND[:ARGS]``
or a scenario's ``[[faults]]``; see :mod:`pressor.contracts.faults` for the names, arguments and defaults).
Everything is timed in ticks of the device's sample period and every random draw comes from a
generator seeded by (fault seed, fault index, tick, write number), so a faulted run is as
repeatable as a clean one - also when the wall-clock retransmissions of the lockstep protocol
add writes.

World faults (applied by :class:`pressor.hil_sim.world.World`)
    ``sensor-*`` become monitor artifacts (:mod:`pressor.hil_sim.devices.sensor`); ``sched-*`` rewrite the
    reported K, T, τ and validity; ``pump-*`` set the pump's injected state each tick.

Link faults (applied by ``pressor.hil_sim.devices.device``)
    ``link-flip``, ``link-drop``, ``link-duplicate``, ``link-garbage`` by :class:`LinkFaultPort`, a
    wrapper of the device's port (writes: frame-aware; reads: byte-wise). ``link-stall`` and
    ``link-disconnect`` by the device loop (:meth:`LinkFaults.link_down`): the device keeps
    simulating but exchanges nothing, so in lockstep the runtime sees a jump of the device's sim
    time and runs its watchdogs over the silent ticks on its virtual clock.
"""

from __future__ import annotations

import random
from collections.abc import Callable, Sequence
from typing import Any

from pressor.contracts.faults import FaultSpec
from pressor.hil_sim.devices.sensor import Artifact
from pressor.link import PortWrapper

__all__ = ["LinkFaultPort", "LinkFaults", "WorldFaults", "split_frames"]

_SENSOR_ARTIFACT = {
    "sensor-nan": "nan",
    "sensor-flatline": "flatline",
    "sensor-flush": "flush",
    "sensor-damped": "damping",
    "sensor-disconnect": "disconnect",
    "sensor-range": "range",
}


def _rng(spec: FaultSpec, tick: int, n: int) -> random.Random:
    return random.Random(((spec.seed * 1_000_003 + spec.index) << 40) + (tick << 12) + n)


class WorldFaults:
    """The sensor, pump and scheduling faults of a schedule, for one world.

    Parameters
    ----------
    specs
        The whole schedule (link faults are ignored here).
    sample_period_s
        The world's tick (s).
    """

    def __init__(self, specs: Sequence[FaultSpec], sample_period_s: float) -> None:
        ts = sample_period_s
        self.artifacts: list[Artifact] = []
        self.sched: list[tuple[int, int, FaultSpec]] = []
        self.pump: list[tuple[int, int, FaultSpec]] = []
        for spec in specs:
            first, end = spec.ticks(ts)
            group = spec.info.group
            if group == "sensor":
                a = spec.args
                kind = _SENSOR_ARTIFACT[spec.kind]
                level = a.get("level_mmhg", a.get("value_mmhg", float("nan")))
                # window edges half a tick early so that float round-off never moves them
                self.artifacts.append(
                    Artifact(
                        kind,
                        (first - 0.5) * ts,
                        (end - first) * ts,
                        level_mmhg=level,
                        time_const_s=a.get("tc_s", 20.0),
                        flag_after_s=a.get("flag_after_s", float("inf")),
                    )
                )
            elif group == "sched":
                self.sched.append((first, end, spec))
            elif group == "pump":
                self.pump.append((first, end, spec))

    def scheduling(
        self, tick: int, K: float, T_s: float, tau_s: float, valid: bool
    ) -> tuple[float, float, float, bool]:
        """The scheduling parameters the device reports at ``tick`` (truth, or faulted)."""
        for first, end, spec in self.sched:
            if first <= tick < end:
                if spec.kind == "sched-missing":
                    nan = float("nan")
                    return nan, nan, nan, False
                if spec.kind == "sched-out-of-box":
                    K = spec.args["K"]
                else:  # sched-jump: square wave at the tick rate
                    amp = spec.args["amplitude"]
                    K = K + (amp if (tick - first) % 2 == 0 else -amp)
        return K, T_s, tau_s, valid

    def pump_state(self, tick: int) -> tuple[bool, bool, bool, float]:
        """``(occluded, empty, ignore_commands, delivery_factor)`` of the pump during ``tick``."""
        occ = empty = ignore = False
        factor = 1.0
        for first, end, spec in self.pump:
            if first <= tick < end:
                if spec.kind == "pump-occlusion":
                    occ = True
                elif spec.kind == "pump-empty":
                    empty = True
                elif spec.kind == "pump-ignore":
                    ignore = True
                else:
                    factor *= spec.args["factor"]
        return occ, empty, ignore, factor


def split_frames(data: bytes) -> list[bytes]:
    """Split a burst of well-formed MAVLink 2 frames (as the session writes them)."""
    out = []
    i, n = 0, len(data)
    while i < n:
        if data[i] != 0xFD or i + 3 > n:
            out.append(data[i:])
            break
        flen = 12 + data[i + 1] + (13 if data[i + 2] & 1 else 0)
        out.append(data[i : i + flen])
        i += flen
    return out


class LinkFaults:
    """The link faults of a schedule: which ticks the link is down, and the port wrapper's view."""

    def __init__(self, specs: Sequence[FaultSpec], sample_period_s: float) -> None:
        self.down: list[tuple[int, int, FaultSpec]] = []
        self.bytewise: list[tuple[int, int, FaultSpec]] = []
        for spec in specs:
            if spec.info.group != "link":
                continue
            first, end = spec.ticks(sample_period_s)
            if spec.kind in ("link-stall", "link-disconnect"):
                self.down.append((first, end, spec))
            else:
                self.bytewise.append((first, end, spec))

    def link_down(self, tick: int) -> FaultSpec | None:
        """The stall/disconnect covering ``tick``, if any."""
        for first, end, spec in self.down:
            if first <= tick < end:
                return spec
        return None

    def starts_at(self, tick: int) -> FaultSpec | None:
        """A stall/disconnect whose first tick is ``tick``."""
        for first, _, spec in self.down:
            if first == tick:
                return spec
        return None

    def ends_at(self, tick: int) -> FaultSpec | None:
        """A stall/disconnect whose last tick was ``tick - 1``."""
        for _, end, spec in self.down:
            if end == tick:
                return spec
        return None

    def active(self, tick: int) -> list[tuple[int, FaultSpec]]:
        """Byte-level faults active at ``tick`` as ``(first tick, spec)``."""
        return [(first, s) for first, end, s in self.bytewise if first <= tick < end]


class LinkFaultPort(PortWrapper):
    """A port wrapper that applies the byte-level link faults of the current tick.

    Parameters
    ----------
    port
        The device's port (pyserial or anything with ``write``/``read``/``in_waiting``).
    faults
        :class:`LinkFaults` of the schedule.
    tick
        Returns the device's current tick (``lambda: world.tick``).

    Attributes
    ----------
    hits
        Count of fault actions per kind (flipped bytes, dropped frames, ...).
    """

    def __init__(self, port: Any, faults: LinkFaults, tick: Callable[[], int]) -> None:
        self._port = port
        self.faults = faults
        self._tick = tick
        self._writes_at: tuple[int, int] = (-1, 0)
        self._reads_at: tuple[int, random.Random | None] = (-1, None)
        self._forced: set[int] = set()
        self.cut_next_write = False
        self.hits: dict[str, int] = {}

    # pyserial subset (timeout, in_waiting, close: PortWrapper) -------------------------------
    def flush(self) -> None:
        flush = getattr(self._port, "flush", None)
        if flush is not None:
            flush()

    def _hit(self, kind: str, n: int = 1) -> None:
        self.hits[kind] = self.hits.get(kind, 0) + n

    def write(self, data: bytes) -> int | None:
        """Write ``data`` after applying the faults active at the current tick."""
        size = len(data)
        if self.cut_next_write:  # disconnect: the burst in flight is cut mid-frame
            self.cut_next_write = False
            self._hit("link-disconnect")
            self._port.write(bytes(data[: max(1, size // 2 + 3)]))
            return size
        tick = self._tick()
        active = self.faults.active(tick)
        if not active:
            return self._port.write(data)
        last_tick, n = self._writes_at
        n = n + 1 if last_tick == tick else 0
        self._writes_at = (tick, n)
        out = bytes(data)
        for _first, spec in active:
            rng = _rng(spec, tick, n)
            forced = spec.index not in self._forced
            self._forced.add(spec.index)
            rate = spec.args.get("rate", 0.0)
            if spec.kind == "link-drop":
                keep = []
                for j, frame in enumerate(split_frames(out)):
                    if (forced and j == 0) or rng.random() < rate:
                        self._hit(spec.kind)
                    else:
                        keep.append(frame)
                out = b"".join(keep)
            elif spec.kind == "link-duplicate":
                frames = split_frames(out)
                if forced or rng.random() < rate:
                    frames.reverse()
                    self._hit(spec.kind)
                dup = []
                for j, frame in enumerate(frames):
                    dup.append(frame)
                    if (forced and j == 0) or rng.random() < rate:
                        dup.append(frame)
                        self._hit(spec.kind)
                out = b"".join(dup)
            elif spec.kind == "link-flip":
                buf = bytearray(out)
                for j in range(len(buf)):
                    if (forced and j == 4) or rng.random() < rate:
                        buf[j] ^= rng.randrange(1, 256)
                        self._hit(spec.kind)
                out = bytes(buf)
            elif spec.kind == "link-garbage":
                k = int(spec.args["bytes"])
                out = rng.randbytes(k) + out
                self._hit(spec.kind, k)
        if out:
            self._port.write(out)
        return size

    def read(self, size: int = 1) -> bytes:
        """Read from the port; byte flips / drops of the active faults apply to what arrives."""
        data = self._port.read(size)
        if not data:
            return data
        tick = self._tick()
        active = [s for _, s in self.faults.active(tick) if s.kind in ("link-flip", "link-drop")]
        if not active:
            return data
        last, rng = self._reads_at
        if last != tick or rng is None:
            rng = _rng(active[0], tick, 4095)
            self._reads_at = (tick, rng)
        buf = bytearray()
        for b in data:
            for spec in active:
                # per byte: flips at the rate; drops at a tenth of the frame rate per byte
                if spec.kind == "link-flip" and rng.random() < spec.args["rate"]:
                    b ^= rng.randrange(1, 256)
                    self._hit("link-flip-read")
                elif spec.kind == "link-drop" and rng.random() < spec.args["rate"] / 10.0:
                    b = -1
                    self._hit("link-drop-read")
                    break
            if b >= 0:
                buf.append(b)
        return bytes(buf)
