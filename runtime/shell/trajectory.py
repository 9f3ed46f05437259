"""What a runtime run keeps: the per-tick trajectory and the run's account (:class:`LoopResult`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pressor.runtime.core.closed_loop import TickRecord


@dataclass
class Trajectory:
    """Per-tick signals of a run, in preallocated arrays that grow by doubling.

    Attributes (after :meth:`arrays`): ``tick``, ``sim_time_s``, ``map_mmhg`` (as measured),
    ``target_mmhg``, ``command_ml_h`` (sent to the pump), ``controller_ml_h`` (the controller's raw
    output, NaN when it did not run), ``delivered_ml_h`` (the rate the pump reported after the
    advance answering the tick, i.e. in the status of the next tick; NaN if that status never
    arrived), ``faults`` (supervisor fault bits), ``state``.
    """

    capacity: int = 1 << 14
    n: int = 0
    ring: bool = False
    data: np.ndarray = field(init=False)

    FIELDS = (
        "tick",
        "sim_time_s",
        "map_mmhg",
        "target_mmhg",
        "command_ml_h",
        "controller_ml_h",
        "delivered_ml_h",
        "faults",
        "state",
    )
    _DELIVERED = FIELDS.index("delivered_ml_h")

    def __post_init__(self) -> None:
        shape = (self.capacity, len(self.FIELDS))
        # a ring is written to once up front, so its pages count in RSS from the start
        self.data = np.full(shape, np.nan) if self.ring else np.empty(shape, dtype=np.float64)

    def append(self, rec: TickRecord, map_mmhg: float) -> None:
        """Store one tick (``map_mmhg`` as recorded); a ring keeps the last ``capacity``."""
        inp, sup = rec.inputs, rec.supervisor
        row = (
            inp.tick,
            inp.sim_time_s,
            map_mmhg,
            inp.target_mmhg,
            sup.command_ml_h,
            rec.controller_ml_h,
            math.nan,
            sup.faults,
            sup.state,
        )
        cap = self.data.shape[0]
        if self.n >= cap:
            if self.ring:
                self.data[self.n % cap] = row
                self.n += 1
                return
            self.data = np.concatenate([self.data, np.empty_like(self.data)])
        self.data[self.n] = row
        self.n += 1

    def last_tick(self) -> int | None:
        """Tick of the newest row (``None`` before the first)."""
        return int(self.data[(self.n - 1) % self.data.shape[0], 0]) if self.n else None

    def delivered(self, status_tick: int, delivered_ml_h: float) -> None:
        """File a pump status of ``status_tick``: the rate delivered over tick ``status_tick − 1``.

        Stored in the newest row if that row is tick ``status_tick − 1``; otherwise ignored.
        """
        if self.n and self.last_tick() == status_tick - 1:
            self.data[(self.n - 1) % self.data.shape[0], self._DELIVERED] = delivered_ml_h

    def arrays(self) -> dict[str, np.ndarray]:
        """Copies of the recorded columns by name (a ring: the last ``capacity`` ticks)."""
        if self.ring and self.n > self.capacity:
            i = self.n % self.capacity
            d = np.concatenate([self.data[i:], self.data[:i]])
        else:
            d = self.data[: self.n]
        out = {name: d[:, i].copy() for i, name in enumerate(self.FIELDS)}
        for name in ("tick", "faults", "state"):
            out[name] = out[name].astype(np.int64)
        return out


def held_delivered_ml_h(delivered_ml_h: np.ndarray) -> np.ndarray:
    """The delivered rate (ml/h) per tick with gaps filled: a tick whose pump status never
    arrived (link stall, the run's last tick cut off) holds the previous reported rate, as the
    pump itself holds its rate while the link is silent; 0 ml/h before the first report."""
    out = np.array(delivered_ml_h, dtype=np.float64)
    known = np.isfinite(out)
    idx = np.where(known, np.arange(out.size), -1)
    np.maximum.accumulate(idx, out=idx)
    return np.where(idx >= 0, out[np.maximum(idx, 0)], 0.0)


@dataclass
class LoopResult:
    """What a run produced: the trajectory, timing, link counters and supervisor account."""

    trajectory: dict[str, np.ndarray]
    timing: dict[str, float | int]
    link: dict[str, int]
    detections: dict[str, int]
    ticks_in_state: dict[str, int]
    transitions: list[dict[str, Any]]
    commands_out_of_range: int
    ended: str
    wall_s: float = 0.0
    #: where the run executed (filled by the CLI: CPU wake-up latency request, CPU pinning)
    host: dict[str, Any] = field(default_factory=dict)
    #: the signal that stopped the run early (:mod:`pressor.runtime.shell.interrupt`), else None
    stop_signal: int | None = None
    #: controller failures the supervisor held on (``pressor run``; :mod:`pressor.runtime.core.events`)
    controller_faults: list[dict[str, Any]] = field(default_factory=list)
    #: what ended the run when it failed (the device stalled, an internal error): the loop sent
    #: the safe command first; the caller keeps the outputs, then raises it
    error: BaseException | None = None
    #: what the loop's boundary checks found (:meth:`pressor.runtime.shell.boundary.Boundary.summary`)
    boundary: dict[str, Any] = field(default_factory=dict)
