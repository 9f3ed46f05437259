"""The simulated patient's true MAP, tick by tick, kept beside the link for the SIL recording.

The runtime sees only what the monitor reports (noise, quantisation, faults); a simulated device
also knows the MAP the monitor measured. ``pressor device --truth-out FILE.npz`` keeps it and
writes it when the device ends (however it ends), and ``pressor sil`` adds it to the runtime's
recording as ``/patient/map_true_mmhg``, so the viewer shows measured and true MAP together. The
pump's delivered rate at each tick is kept beside it (``rate_ml_h``): ``pressor sil`` turns it into
the dose delivered in µg/min and µg/kg/min for the viewer's dose panel.
Nothing of it crosses the link: the protocol stays what a real monitor can send.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from pressor.plumbing.files import write_atomic


class TruthLog:
    """True MAP per tick, preallocated by :meth:`reserve` (nothing grows while the run goes)."""

    def __init__(self) -> None:
        self.reserve(0)

    def reserve(self, n_ticks: int) -> None:
        """Make room for ``n_ticks`` (>= 0) ticks, dropping what was recorded; the device calls
        it once it knows the run's length."""
        if n_ticks < 0:
            raise ValueError(f"n_ticks={n_ticks!r} must be >= 0")
        self._ticks = np.zeros(n_ticks, dtype=np.int64)
        self._times = np.zeros(n_ticks, dtype=np.float64)
        self._map = np.zeros(n_ticks, dtype=np.float64)
        self._rate = np.full(n_ticks, np.nan, dtype=np.float64)
        self._n = 0

    def record(
        self, tick: int, sim_time_s: float, map_true_mmhg: float, rate_ml_h: float = np.nan
    ) -> None:
        """Keep tick ``tick``'s true MAP (mmHg) and the pump's delivered rate (ml/h) at
        ``sim_time_s`` (s); ticks past the reserved count are ignored."""
        n = self._n
        if n < len(self._ticks):
            self._ticks[n], self._times[n], self._map[n] = tick, sim_time_s, map_true_mmhg
            self._rate[n] = rate_ml_h
            self._n = n + 1

    def save(self, path: str | Path) -> None:
        """Write the ticks recorded so far as ``.npz`` (``tick``, ``sim_time_s``,
        ``map_true_mmhg``, ``rate_ml_h``), atomically."""
        buf = io.BytesIO()
        n = self._n
        np.savez(
            buf,
            tick=self._ticks[:n],
            sim_time_s=self._times[:n],
            map_true_mmhg=self._map[:n],
            rate_ml_h=self._rate[:n],
        )
        write_atomic(Path(path), buf.getvalue())


def load_truth(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(tick, sim_time_s, map_true_mmhg)`` from a file :meth:`TruthLog.save` wrote."""
    with np.load(path) as data:
        return data["tick"], data["sim_time_s"], data["map_true_mmhg"]


def load_truth_rate(path: str | Path) -> np.ndarray | None:
    """The pump's delivered rate per tick (ml/h) from a file :meth:`TruthLog.save` wrote, on the
    ticks of :func:`load_truth`; ``None`` for a file without it."""
    with np.load(path) as data:
        return data["rate_ml_h"] if "rate_ml_h" in data.files else None
