"""What a reward sees of a step (:class:`Ticks`) and the default reward (:class:`MapReward`).

A reward is any callable ``reward(ticks: Ticks) -> float``, called once per environment step with
the control ticks that step ran (one per 0.1 s at the default 10 Hz loop). The default,
:class:`MapReward`, judges the *true* MAP against the clinical ±5 mmHg band of
``docs/METRICS.md`` (``time_in_band_pct``'s band), penalises hypotension and overshoot by how far
MAP is outside the band, and charges the drug delivered::

    e_k = true MAP_k − target_k                                   (mmHg)
    r   = Σ_k Ts · ( w_band · [|e_k| ≤ b]
                   − w_hypo · max(0, −e_k − b)
                   − w_over · max(0,  e_k − b)
                   − w_drug · rate_k / rate_max )

with Ts the loop period (s), b = 5 mmHg, rate_k the pump's mean delivered rate over tick k (ml/h)
and rate_max the pump limit (ml/h). Every term is per second of patient time, so the return does
not depend on how many ticks an action lasts: with the default weights an episode's band term is
its time in band in seconds, an hour at 10 mmHg below the target costs 0.2·5·3600 = 3600, and an
hour at the pump's limit 0.1·3600 = 360.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["COLUMNS", "MapReward", "Ticks"]


#: the per-tick columns of :class:`Ticks`, in order, with their dtypes
COLUMNS: dict[str, type] = {
    "t_s": np.float64,
    "map_mmhg": np.float64,
    "quality": np.int64,
    "map_true_mmhg": np.float64,
    "target_mmhg": np.float64,
    "command_ml_h": np.float64,
    "rate_ml_h": np.float64,
    "delivered_ml_h": np.float64,
    "alarms": np.int64,
    "state": np.int64,
    "faults": np.int64,
}


class Ticks:
    """Control ticks of the loop, oldest first: one environment step's, or a whole episode's.

    Every column is a numpy array with one entry per tick k (sampled at the tick, the command held
    over it), with the names and units of :class:`pressor.hil_sim.episode.Trajectory`. Build one from arrays
    (``Ticks(t_s=..., ..., period_s=..., max_rate_ml_h=...)``); the environment builds its own
    from its record with :meth:`of_record`, and then makes each array only when it is read (most
    steps' rewards read three of the eleven). :meth:`values` gives a column as a Python list, the
    fast way for a reward written in plain Python.

    Attributes
    ----------
    t_s
        Tick times (s).
    map_mmhg
        Measured MAP as the device sent it (mmHg; NaN when the monitor had no value).
    quality
        The sample's monitor quality bits (:mod:`pressor.contracts.faults`).
    map_true_mmhg
        True MAP (mmHg): what the patient experiences.
    target_mmhg
        Target (mmHg).
    command_ml_h
        Command the pump received (ml/h, float32): the supervisor's, from the agent's action.
    rate_ml_h
        Mean delivered rate over the tick (ml/h).
    delivered_ml_h
        Delivered rate (ml/h) of the pump status after the tick.
    alarms
        Pump alarm bits after the tick.
    state, faults
        Supervisor state (:class:`pressor.runtime.core.supervisor_config.State`) and fault bits at the tick.
    period_s
        Loop period Ts (s).
    max_rate_ml_h
        The pump's limit (ml/h).
    """

    __slots__ = ("_arrays", "_record", "_a", "_b", "period_s", "max_rate_ml_h")

    t_s: np.ndarray
    map_mmhg: np.ndarray
    quality: np.ndarray
    map_true_mmhg: np.ndarray
    target_mmhg: np.ndarray
    command_ml_h: np.ndarray
    rate_ml_h: np.ndarray
    delivered_ml_h: np.ndarray
    alarms: np.ndarray
    state: np.ndarray
    faults: np.ndarray

    def __init__(
        self,
        t_s: np.ndarray,
        map_mmhg: np.ndarray,
        quality: np.ndarray,
        map_true_mmhg: np.ndarray,
        target_mmhg: np.ndarray,
        command_ml_h: np.ndarray,
        rate_ml_h: np.ndarray,
        delivered_ml_h: np.ndarray,
        alarms: np.ndarray,
        state: np.ndarray,
        faults: np.ndarray,
        period_s: float,
        max_rate_ml_h: float,
    ) -> None:
        columns = (
            t_s, map_mmhg, quality, map_true_mmhg, target_mmhg, command_ml_h, rate_ml_h,
            delivered_ml_h, alarms, state, faults,
        )  # fmt: skip
        self._arrays = {
            name: np.asarray(column, dtype)
            for (name, dtype), column in zip(COLUMNS.items(), columns, strict=True)
        }
        n = {len(a) for a in self._arrays.values()}
        if len(n) != 1:
            raise ValueError(f"Ticks: the columns have different lengths {sorted(n)}")
        self._record: Mapping[str, list[Any]] | None = None
        self._a = self._b = 0
        self.period_s = float(period_s)
        self.max_rate_ml_h = float(max_rate_ml_h)

    @classmethod
    def of_record(
        cls,
        record: Mapping[str, list[Any]],
        a: int,
        b: int,
        period_s: float,
        max_rate_ml_h: float,
    ) -> Ticks:
        """Ticks ``a`` to ``b - 1`` of ``record`` (a list per :data:`COLUMNS` name); the
        record's entries in that range must not change afterwards (arrays are made when read)."""
        ticks = cls.__new__(cls)
        ticks._arrays = {}
        ticks._record = record
        ticks._a, ticks._b = a, b
        ticks.period_s = period_s
        ticks.max_rate_ml_h = max_rate_ml_h
        return ticks

    def __len__(self) -> int:
        return self._b - self._a if self._record is not None else len(self._arrays["t_s"])

    def __getattr__(self, name: str) -> np.ndarray:
        # reached for the columns (annotations only, no class attributes): made once, when read
        if name not in COLUMNS:
            raise AttributeError(f"Ticks has no attribute {name!r}")
        array = self._arrays.get(name)
        if array is None:
            record = self._record
            assert record is not None  # built from arrays: every column is in _arrays
            array = self._arrays[name] = np.array(record[name][self._a : self._b], COLUMNS[name])
        return array

    def values(self, name: str) -> list[Any]:
        """The column ``name`` (one of :data:`COLUMNS`) as a Python list."""
        if name not in COLUMNS:
            raise KeyError(f"Ticks has no column {name!r}: allowed {', '.join(COLUMNS)}")
        record = self._record
        if record is None or name in self._arrays:
            return getattr(self, name).tolist()
        return record[name][self._a : self._b]  # a list slice is already a copy


@dataclass(frozen=True)
class MapReward:
    """The default reward (formula in the module docstring); weights are keyword arguments.

    Parameters
    ----------
    band_mmhg
        Half-width b of the band around the target (mmHg), > 0.
    in_band
        w_band: reward per second with the true MAP in the band (1/s).
    hypotension
        w_hypo: penalty per mmHg below the band, per second (1/(mmHg·s)).
    overshoot
        w_over: penalty per mmHg above the band, per second (1/(mmHg·s)).
    drug
        w_drug: penalty per second at the pump's limit, proportional to the rate (1/s).
    """

    band_mmhg: float = 5.0
    in_band: float = 1.0
    hypotension: float = 0.2
    overshoot: float = 0.05
    drug: float = 0.1

    def __post_init__(self) -> None:
        if not self.band_mmhg > 0.0:
            raise ValueError(f"band_mmhg = {self.band_mmhg!r}: allowed > 0 mmHg")

    def terms(self, ticks: Ticks) -> dict[str, float]:
        """The four signed terms of the reward over ``ticks``: ``in_band`` (≥ 0),
        ``hypotension``, ``overshoot`` and ``drug`` (≤ 0); the reward is their sum."""
        b = self.band_mmhg
        ts = ticks.period_s
        in_band = 0.0
        below = 0.0
        above = 0.0
        true_map, target = ticks.values("map_true_mmhg"), ticks.values("target_mmhg")
        for m, t in zip(true_map, target, strict=True):
            e = m - t
            if -b <= e <= b:
                in_band += 1.0
            elif e < -b:
                below += -e - b
            elif e > b:
                above += e - b
        drug = sum(ticks.values("rate_ml_h")) / ticks.max_rate_ml_h
        return {
            "in_band": self.in_band * ts * in_band,
            "hypotension": -self.hypotension * ts * below,
            "overshoot": -self.overshoot * ts * above,
            "drug": -self.drug * ts * drug,
        }

    def __call__(self, ticks: Ticks) -> float:
        """The reward over ``ticks`` (the sum of :meth:`terms`)."""
        return sum(self.terms(ticks).values())
