"""What a runtime run keeps: the per-tick trajectory and the run's account (:class:`LoopResult`)."""

from __future__ import annotations

import bisect
import math
from array import array
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pressor.runtime.core.closed_loop import TickRecord

#: rows per block of a float column: the most a column holds beyond its rows
_CHUNK_ROWS = 4096


def _same(a: float, b: float) -> bool:
    """``a`` and ``b`` are the same value (NaN is NaN; 0.0 and -0.0 differ)."""
    if a != a or b != b:  # NaN
        return a != a and b != b
    return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)


class _Floats:
    """A float column in blocks of :data:`_CHUNK_ROWS` rows: float32 while every value is one
    exactly (a MAP or a delivered rate as the wire carries them), float64 from the first value
    that is not (the whole column converted then), so the values read back are the ones stored."""

    def __init__(self) -> None:
        self.blocks: list[np.ndarray] = []
        self.base = 0  # the row of blocks[0][0]
        self.n = 0

    def _put(self, row: int, value: float) -> None:
        block, i = divmod(row - self.base, _CHUNK_ROWS)
        data = self.blocks[block]
        data[i] = value
        if data.dtype == np.float32 and not _same(float(data[i]), value):
            self.blocks = [b.astype(np.float64) for b in self.blocks]
            self.blocks[block][i] = value

    def append(self, value: float) -> None:
        if self.n - self.base == len(self.blocks) * _CHUNK_ROWS:
            dtype = self.blocks[-1].dtype if self.blocks else np.float32
            self.blocks.append(np.zeros(_CHUNK_ROWS, dtype=dtype))
        self.n += 1
        self._put(self.n - 1, value)

    def set_last(self, value: float) -> None:
        self._put(self.n - 1, value)

    def drop_blocks(self, count: int) -> None:
        del self.blocks[:count]
        self.base += count * _CHUNK_ROWS

    def values(self, lo: int, hi: int) -> np.ndarray:
        if not self.blocks:
            return np.empty(0)
        whole = np.concatenate(self.blocks)
        return whole[lo - self.base : hi - self.base].astype(np.float64)

    @property
    def nbytes(self) -> int:
        return sum(b.nbytes for b in self.blocks)


class _Steps:
    """A piecewise-constant column (a target, a state, fault bits, a tick's offset from its
    row): the row where each new value starts, and the value."""

    def __init__(self, code: str) -> None:
        self.starts = array("q")
        self.vals = array(code)

    def append(self, row: int, value: float) -> None:
        if not self.vals or not _same(self.vals[-1], value):
            self.starts.append(row)
            self.vals.append(value)

    def last(self) -> float:
        return self.vals[-1]

    def drop_before(self, row: int) -> None:
        k = bisect.bisect_right(self.starts, row) - 1  # the step that holds ``row`` stays
        if k > 0:
            del self.starts[:k]
            del self.vals[:k]

    def values(self, lo: int, hi: int) -> np.ndarray:
        vals = np.frombuffer(self.vals, dtype=np.dtype(self.vals.typecode)) if self.vals else None
        if vals is None or hi <= lo:
            return np.empty(0, dtype=np.float64 if self.vals.typecode == "d" else np.int64)
        starts = np.frombuffer(self.starts, dtype=np.int64)
        idx = np.searchsorted(starts, np.arange(lo, hi), side="right") - 1
        return vals[np.maximum(idx, 0)].copy()

    @property
    def nbytes(self) -> int:
        return (len(self.starts) + len(self.vals)) * 8


class _Times:
    """The sample times: ``tick × period`` as the simulated device and the silent ticks send
    them (nothing stored), with the rows that differ kept; a column of its own (:class:`_Floats`)
    once more than a quarter of the rows differ (a device with its own clock).

    The rule is the one the device's times show at their first tick after 0: ``tick × period``
    in float64, or rounded to float32 (a time that went through a float32), with the run's
    period or the one that tick gives (``time / tick``)."""

    def __init__(self, period_s: float) -> None:
        self.period_s = period_s
        self.f32 = False  # the prediction rounded to float32
        self.learned = False
        self.rows = array("q")
        self.vals = array("d")
        self.floats: _Floats | None = None

    def _predict(self, tick: int) -> float:
        t = tick * self.period_s
        return float(np.float32(t)) if self.f32 else t

    def _learn(self, tick: int, value: float) -> None:
        """Fix the rule at the first tick ≥ 3 with a finite time (ticks 1 and 2 cannot tell
        a float32 period from a float32 time; the rows before are all kept)."""
        self.learned = True
        p32 = float(np.float32(self.period_s))
        for period_s, f32 in (
            (self.period_s, False),
            (self.period_s, True),
            (p32, False),
            (p32, True),
            (value / tick, False),
        ):
            t = tick * period_s
            if (float(np.float32(t)) if f32 else t) == value:
                self.period_s, self.f32 = period_s, f32
                return

    def append(self, row: int, tick: int, value: float) -> None:
        if not self.learned and tick >= 3 and math.isfinite(value):
            self._learn(tick, value)
        if self.floats is not None:
            self.floats.append(value)
        elif not self.learned or not _same(self._predict(tick), value):
            self.rows.append(row)
            self.vals.append(value)

    def own_column(self, base: int, n: int, ticks: np.ndarray) -> None:
        """Store every time from now on (``ticks``: the rows ``base`` … ``n − 1``)."""
        floats = _Floats()
        floats.base = floats.n = base
        for t in self.values(base, n, ticks):
            floats.append(float(t))
        self.floats = floats
        self.rows, self.vals = array("q"), array("d")

    def drop_before(self, row: int) -> None:
        k = bisect.bisect_left(self.rows, row)
        del self.rows[:k]
        del self.vals[:k]

    def values(self, lo: int, hi: int, ticks: np.ndarray) -> np.ndarray:
        if self.floats is not None:
            return self.floats.values(lo, hi)
        out = ticks.astype(np.float64) * self.period_s
        if self.f32:
            out = out.astype(np.float32).astype(np.float64)
        rows = np.frombuffer(self.rows, dtype=np.int64) if self.rows else np.empty(0, np.int64)
        keep = (rows >= lo) & (rows < hi)
        if keep.any():
            out[rows[keep] - lo] = np.frombuffer(self.vals, dtype=np.float64)[keep]
        return out

    @property
    def nbytes(self) -> int:
        own = self.floats.nbytes if self.floats is not None else 0
        return own + (len(self.rows) + len(self.vals)) * 8


class Trajectory:
    """Per-tick signals of a run, kept losslessly in little memory: what changes every tick in
    float32 while the values are float32 exactly (MAP and the delivered rate come as float32 on
    the wire), the rest as steps (the target, state, fault bits) or as the rule they follow (a
    sample's time is ``tick × period``; the ticks follow on), with what departs from it kept.

    About 16 bytes per tick (0.6 MB per hour at 10 Hz; 0.9 MB with a device that sends its own
    times), against 72 for every column in float64: ``pressor run``'s memory grows by less than
    1 MB per hour (``benchmarks/memory_soak.py``), while every value read back by :meth:`arrays`
    is the one stored, so the summary's figures are those of the whole run.

    Attributes (after :meth:`arrays`): ``tick``, ``sim_time_s``, ``map_mmhg`` (as measured),
    ``target_mmhg``, ``command_ml_h`` (sent to the pump), ``delivered_ml_h`` (the rate the pump
    reported after the advance answering the tick, i.e. in the status of the next tick; NaN if
    that status never arrived), ``faults`` (supervisor fault bits), ``state``. The controller's
    raw output is not kept here: the recording has it (``/controller/command_ml_h``).

    Parameters
    ----------
    capacity
        With ``ring``: keep only the last this-many ticks (the memory of soak runs that must not
        grow at all; the oldest blocks of :data:`_CHUNK_ROWS` are dropped as they fall out).
    ring
        Keep the last ``capacity`` ticks only; else every tick.
    period_s
        The sample period (s): times equal to ``tick × period_s`` are not stored.
    """

    FIELDS = (
        "tick",
        "sim_time_s",
        "map_mmhg",
        "target_mmhg",
        "command_ml_h",
        "delivered_ml_h",
        "faults",
        "state",
    )

    def __init__(self, capacity: int = 1 << 14, ring: bool = False, period_s: float = 0.1):
        self.capacity = int(capacity)
        self.ring = ring
        self.n = 0
        self.base = 0  # the oldest row kept (a ring drops older ones)
        self._tick = _Steps("q")  # tick − row
        self._time = _Times(float(period_s))
        self._map = _Floats()
        self._target = _Steps("d")
        self._command = _Floats()
        self._delivered = _Floats()
        self._faults = _Steps("q")
        self._state = _Steps("q")

    def append(self, rec: TickRecord, map_mmhg: float) -> None:
        """Store one tick (``map_mmhg`` as recorded); a ring keeps the last ``capacity``."""
        inp, sup = rec.inputs, rec.supervisor
        row, tick = self.n, int(inp.tick)
        self._tick.append(row, tick - row)
        self._time.append(row, tick, float(inp.sim_time_s))
        self._map.append(float(map_mmhg))
        self._target.append(row, float(inp.target_mmhg))
        self._command.append(float(sup.command_ml_h))
        self._delivered.append(math.nan)
        self._faults.append(row, int(sup.faults))
        self._state.append(row, int(sup.state))
        self.n += 1
        if self._time.floats is None and len(self._time.rows) > max(64, (self.n - self.base) // 4):
            self._time.own_column(self.base, self.n, self._ticks(self.base, self.n))
        if self.ring and self.n - self.base >= self.capacity + _CHUNK_ROWS:
            self._drop_block()

    def _drop_block(self) -> None:
        """A ring: forget the oldest block of rows (every column)."""
        self.base += _CHUNK_ROWS
        for col in (self._map, self._command, self._delivered, self._time.floats):
            if col is not None:
                col.drop_blocks(1)
        for steps in (self._tick, self._target, self._faults, self._state):
            steps.drop_before(self.base)
        self._time.drop_before(self.base)

    def _ticks(self, lo: int, hi: int) -> np.ndarray:
        return self._tick.values(lo, hi) + np.arange(lo, hi, dtype=np.int64)

    def last_tick(self) -> int | None:
        """Tick of the newest row (``None`` before the first)."""
        return int(self._tick.last()) + self.n - 1 if self.n else None

    def delivered(self, status_tick: int, delivered_ml_h: float) -> None:
        """File a pump status of ``status_tick``: the rate delivered over tick ``status_tick − 1``.

        Stored in the newest row if that row is tick ``status_tick − 1``; otherwise ignored.
        """
        if self.n and self.last_tick() == status_tick - 1:
            self._delivered.set_last(float(delivered_ml_h))

    @property
    def nbytes(self) -> int:
        """The bytes the kept columns hold (the memory the trajectory grows by)."""
        cols = (self._tick, self._time, self._map, self._target, self._command, self._delivered)
        return sum(c.nbytes for c in (*cols, self._faults, self._state))

    def arrays(self) -> dict[str, np.ndarray]:
        """The recorded columns by name, new arrays (a ring: the last ``capacity`` ticks)."""
        lo, hi = self.base, self.n
        if self.ring:
            lo = max(lo, hi - self.capacity)
        ticks = self._ticks(lo, hi)
        return {
            "tick": ticks,
            "sim_time_s": self._time.values(lo, hi, ticks),
            "map_mmhg": self._map.values(lo, hi),
            "target_mmhg": self._target.values(lo, hi),
            "command_ml_h": self._command.values(lo, hi),
            "delivered_ml_h": self._delivered.values(lo, hi),
            "faults": self._faults.values(lo, hi),
            "state": self._state.values(lo, hi),
        }


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
    #: the bytes the run's kept trajectory held at its end (:attr:`Trajectory.nbytes`)
    kept_bytes: int = 0
