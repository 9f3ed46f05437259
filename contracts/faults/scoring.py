"""Scoring injected faults from the supervisor's per-tick log: detection, latency, safe state.

:func:`fault_report` scores whole arrays; :class:`FaultScorer` is the streaming form (one tick at a
time, O(faults) memory) for long soak runs.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pressor.contracts.faults.spec import FaultSpec


class FaultScorer:
    """Streaming version of :func:`fault_report`: O(faults) memory, fed one tick at a time.

    Feed every tick in order with :meth:`update`; :meth:`report` gives the same list
    :func:`fault_report` computes from whole arrays (used by long soak runs that do not keep the
    trajectory).
    """

    def __init__(
        self,
        specs: list[FaultSpec],
        fault_bit: dict[str, int],
        sample_period_s: float,
        scheduled: bool,
        auto_state: int = 1,
        recovering_state: int = 4,
    ) -> None:
        self.ts = sample_period_s
        self.auto = auto_state
        self.recovering = recovering_state
        self._prev_cmd: float | None = None
        self._items = []
        for spec in specs:
            info = spec.info
            first, end = spec.ticks(sample_period_s)
            bound = info.bound_at(sample_period_s)
            mask = 0
            for name in info.detected_as:
                mask |= fault_bit[name]
            entry: dict[str, Any] = {
                "kind": spec.kind,
                "start_tick": first,
                "end_tick": end,
                "detected_tick": None,
                "detected_as": [],
                "latency_ticks": None,
                "bound_ticks": bound,
                "within_bound": None,
                "safe_state_s": 0.0,
                "reentry_tick": None,
                "max_reentry_step_ml_h": 0.0,
                "alarm": False,
                "applicable": scheduled or not info.scheduled_only,
            }
            limit = end + (bound or 0) + int(round(2.0 / sample_period_s))
            # phase: 0 waiting, 1 in safe state, 2 done
            self._items.append(
                {
                    "e": entry,
                    "mask": mask,
                    "limit": limit,
                    "phase": 0,
                    "names": info.detected_as,
                    "bits": fault_bit,
                    "rec": False,
                }
            )

    def update(self, tick: int, state: int, faults: int, command: float) -> None:
        """One tick: supervisor state, fault bits and command (ml/h)."""
        prev = self._prev_cmd
        step = 0.0 if prev is None else abs(command - prev)
        self._prev_cmd = command
        for it in self._items:
            e = it["e"]
            if it["phase"] == 2 or not e["applicable"] or tick < e["start_tick"]:
                continue
            if it["phase"] == 0:
                if tick >= it["limit"]:
                    it["phase"] = 2
                    continue
                if faults & it["mask"]:
                    e["detected_tick"] = tick
                    e["detected_as"] = [n for n in it["names"] if faults & it["bits"][n]]
                    e["latency_ticks"] = tick - e["start_tick"]
                    bound = e["bound_ticks"]
                    e["within_bound"] = None if bound is None else e["latency_ticks"] <= bound
                    e["alarm"] = True
                    it["phase"] = 2 if state == self.auto else 1
                    it["since"] = tick
                continue
            # phase 1: in the safe state until AUTO again
            if state == self.recovering and not it["rec"]:
                it["rec"] = True
                e["max_reentry_step_ml_h"] = max(e["max_reentry_step_ml_h"], step)
            elif it["rec"]:
                e["max_reentry_step_ml_h"] = max(e["max_reentry_step_ml_h"], step)
            if state == self.auto:
                if not it["rec"]:
                    e["max_reentry_step_ml_h"] = max(e["max_reentry_step_ml_h"], step)
                e["reentry_tick"] = tick
                e["safe_state_s"] = float((tick - it["since"]) * self.ts)
                it["phase"] = 2
            else:
                e["safe_state_s"] = float((tick + 1 - it["since"]) * self.ts)

    def report(self) -> list[dict[str, Any]]:
        """The scored list (see :func:`fault_report`)."""
        return [dict(it["e"]) for it in self._items]


def fault_report(
    specs: list[FaultSpec],
    trajectory: dict[str, np.ndarray],
    fault_bit: dict[str, int],
    sample_period_s: float,
    scheduled: bool,
    auto_state: int = 1,
    recovering_state: int = 4,
) -> list[dict[str, Any]]:
    """Score each injected fault from the run's per-tick supervisor log.

    Parameters
    ----------
    specs
        The schedule (what ``--fault`` said).
    trajectory
        The loop's arrays: ``tick``, ``command_ml_h``, ``state``, ``faults`` (supervisor bits).
    fault_bit
        Supervisor fault name -> bit.
    sample_period_s
        Loop period (s).
    scheduled
        Whether the controller uses K, T, τ (else scheduling faults are not applicable).

    Returns
    -------
    list of dict
        Per fault: ``kind``, ``start_tick``, ``end_tick``, ``detected_tick`` (first tick at or after
        the start with one of the kind's detection bits; ``None`` if never), ``detected_as``,
        ``latency_ticks``, ``bound_ticks``, ``within_bound``, ``safe_state_s`` (time from detection
        until the supervisor is back in AUTO, s), ``reentry_tick`` (that AUTO tick),
        ``max_reentry_step_ml_h`` (largest |Δ command| from entering RECOVERING through the first
        AUTO tick), ``alarm`` (the detection raised the alarm), ``applicable``.
    """
    scorer = FaultScorer(specs, fault_bit, sample_period_s, scheduled, auto_state, recovering_state)
    update = scorer.update
    for k, st, fb, c in zip(
        trajectory["tick"].tolist(),
        trajectory["state"].tolist(),
        trajectory["faults"].tolist(),
        trajectory["command_ml_h"].tolist(),
        strict=True,
    ):
        update(k, st, fb, c)
    return scorer.report()
