"""How close can any estimated schedule get to the oracle? The start-up bound, measured.

Usage::

    python -m research.estimation_bound                        # 40 patients, seed 11, 2 jobs
    python -m research.estimation_bound --patients 100 --seed 2026 --switch-s 30,40,50,60

Each patient of the seeded cohort runs the shipped LPV in ``--scenario`` (default
``paper-tracking``) under several scheduling sources, through the trial's own closed loop
(:func:`pressor.hil_sim.episode.simulate`, the runtime's core):

``oracle``
    The simulator's true K, T, τ from the first tick (the denominator of every ratio).
``estimated``
    The shipped online estimator (:class:`pressor.runtime.estimation.sources.EstimatedSchedule`).
``K from 0 s``
    The estimator's T and τ, but the true K from the first tick: which parameter the gap is made of.
``truth from S s``
    The estimated source's start-up schedule (the prior's cautious corner, what it schedules while
    learning) until S s, then the true K, T, τ: a source that learns *perfectly* S s into the step.
    No estimator that learns from the MAP can do better than this row for an S after the MAP first
    moves, because before that the data hold nothing about the patient.
``true K from S s``
    The shipped estimator's schedule until S s, then the true K (the estimator's T and τ): what a
    perfect K *after* the start-up would be worth (``--late-k-s``).

It also prints where the estimated source's excess IAE over the oracle accrues: the sums over
patients of IAE(estimated) − IAE(oracle) in the phases [0, 50) s, [50, 200) s and from 200 s on, as
shares of the whole excess (the start-up transient, its landing, the settled loop).

Printed per source: the median over reachable patients of IAE(source)/IAE(oracle) (and the
90th percentile), and the median times (s) at which the MAP first moved by 0.5 mmHg and at which
the estimator first reported a learned estimate. The generated module limits the rate of the
feedback's scheduled ρ to the certificate's bounds (K 2e-4 per s), so a switch moves the prefilter
at once and the feedback slowly, exactly as a real estimate does.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys

import numpy as np

from pressor.hil_sim.episode import simulate
from pressor.hil_sim.patients.cohort import cohort_seeds
from pressor.hil_sim.scenarios.scenario import load_scenario
from pressor.hil_sim.world import World
from pressor.plumbing.parallel import run_ordered
from pressor.runtime.core.scheduling import OracleSchedule, Schedule, ScheduleInput
from pressor.runtime.estimation.sources import EstimatedSchedule
from pressor.runtime.inputs.controller_loader import load_controller

TS = 0.1  # s, the loop's sample period
MOVED_MMHG = 0.5  # MAP change from the first sample that counts as "the MAP has moved"


class PartialTruth:
    """The estimated source with some of its values replaced by the device's truth.

    Parameters
    ----------
    truth_fields
        Which of ``"K"``, ``"T_s"``, ``"tau_s"`` come from the device (none: the shipped source,
        unchanged).
    from_s
        From which time (s) on.
    startup
        Before ``from_s``: True, the start-up schedule (the prior's cautious corner) for every
        field, whatever the estimator reports; False, the estimator's schedule.
    """

    source = "estimated"

    def __init__(self, truth_fields: tuple[str, ...], from_s: float, startup: bool = True) -> None:
        self._est = EstimatedSchedule(sample_period_s=TS)
        self._fields = truth_fields
        self._use_startup = startup
        self._from_tick = round(from_s / TS)
        self._tick = 0
        K, T = self._est.cautious(self._est.estimator.estimate)
        self._startup = (K, T, self._est.estimator.estimate.tau_s)
        self.learned_s = float("nan")

    def update(self, inputs: ScheduleInput) -> Schedule:
        """The estimator's schedule, with the chosen fields from the device from ``from_s`` on."""
        sched = self._est.update(inputs)
        if not sched.from_prior and math.isnan(self.learned_s):
            self.learned_s = self._tick * TS
        self._tick += 1
        if not self._fields:
            return sched
        if self._tick <= self._from_tick:
            if not self._use_startup:
                return sched
            return Schedule(*self._startup, "estimated", True, True, True, "learning")
        truth = {"K": inputs.device_K, "T_s": inputs.device_T_s, "tau_s": inputs.device_tau_s}
        K, T, tau = (
            truth[f] if f in self._fields else getattr(sched, f) for f in ("K", "T_s", "tau_s")
        )
        return Schedule(K, T, tau, "estimated", True, True, False, "ok")


#: phase edges (s) of the excess-IAE breakdown: start-up transient, its landing, settled loop
PHASES_S = (0.0, 50.0, 200.0, math.inf)


def _sources(
    switch_s: list[float], late_k_s: list[float]
) -> list[tuple[str, tuple[str, ...], float, bool]]:
    """(row name, fields from the truth, from s, start-up schedule before) of every source."""
    rows = [("estimated", (), 0.0, True), ("K from 0 s", ("K",), 0.0, True)]
    rows += [(f"truth from {s:g} s", ("K", "T_s", "tau_s"), s, True) for s in switch_s]
    rows += [(f"true K from {s:g} s", ("K",), s, False) for s in late_k_s]
    return rows


def _patient(task: tuple[str, int, list[float], list[float]]) -> dict[str, float] | None:
    """IAE ratios (source / oracle) of one patient, the MAP's first move and the learn time (s),
    and the estimated source's excess IAE (mmHg·s) per phase of :data:`PHASES_S`."""
    scenario_name, seed, switch_s, late_k_s = task
    scenario = load_scenario(scenario_name)

    def iae(schedule: OracleSchedule | PartialTruth) -> tuple[np.ndarray, np.ndarray]:
        """IAE (mmHg·s) per phase, and the true MAP (mmHg)."""
        world = World(scenario, seed, TS)
        traj = simulate(world, load_controller("lpv", TS), schedule=schedule)
        err = np.abs(traj.map_true_mmhg - traj.target_mmhg) * TS
        edges = np.searchsorted(traj.t_s, PHASES_S[1:-1])
        return np.array([part.sum() for part in np.split(err, edges)]), traj.map_true_mmhg

    if not World(scenario, seed, TS).reachable():
        return None
    oracle, map_mmhg = iae(OracleSchedule())
    moved = np.flatnonzero(np.abs(map_mmhg - map_mmhg[0]) > MOVED_MMHG)
    out = {"moved_s": float(moved[0]) * TS if moved.size else float("nan")}
    for name, fields, from_s, startup in _sources(switch_s, late_k_s):
        src = PartialTruth(fields, from_s, startup)
        phases = iae(src)[0]
        out[name] = float(phases.sum() / oracle.sum())
        if name == "estimated":
            out["learned_s"] = src.learned_s
            for k, excess in enumerate(phases - oracle):
                out[f"excess {k}"] = float(excess)
    return out


def main() -> None:
    """Parse the arguments, run the cohort under every source, print the ratios."""
    ap = argparse.ArgumentParser(
        description=__doc__.splitlines()[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    ap.add_argument("--patients", type=int, default=40, help="cohort size, >= 1")
    ap.add_argument("--seed", type=int, default=11, help="cohort seed")
    ap.add_argument("--scenario", default="paper-tracking", help="scenario name or TOML path")
    ap.add_argument(
        "--switch-s", default="30,40,50,60", help="times (s, >= 0) at which the truth takes over"
    )
    ap.add_argument(
        "--late-k-s",
        default="100,200",
        help="times (s, >= 0) from which the true K replaces the estimated one (empty: no rows)",
    )
    ap.add_argument("--jobs", type=int, default=2, help="local worker processes, >= 1")
    args = ap.parse_args()
    if args.patients < 1 or args.jobs < 1:
        ap.error(f"--patients={args.patients} and --jobs={args.jobs} must be >= 1")
    switch_s = _times(ap, "--switch-s", args.switch_s)
    late_k_s = _times(ap, "--late-k-s", args.late_k_s)
    load_scenario(args.scenario)  # a bad name fails here, with the scenario module's message
    tasks = [(args.scenario, s, switch_s, late_k_s) for s in cohort_seeds(args.seed, args.patients)]

    def progress(done: int, total: int) -> None:
        print(f"\r{done}/{total} patients", end="", file=sys.stderr, flush=True)

    rows = [r for r in run_ordered(_patient, tasks, jobs=args.jobs, progress=progress) if r]
    print(file=sys.stderr)
    print(
        f"{args.scenario}, cohort seed {args.seed}: {len(rows)} of {args.patients} patients "
        f"reachable; MAP first moved (> {MOVED_MMHG} mmHg) at median "
        f"{statistics.median(r['moved_s'] for r in rows):.1f} s; the estimator learned at median "
        f"{statistics.median(r['learned_s'] for r in rows):.1f} s"
    )
    print(f"{'source':20s} {'IAE / oracle':>13s} {'p90':>6s}")
    for name, *_ in _sources(switch_s, late_k_s):
        ratios = [r[name] for r in rows]
        print(f"{name:20s} {statistics.median(ratios):13.3f} {np.percentile(ratios, 90):6.2f}")
    excess = [sum(r[f"excess {k}"] for r in rows) for k in range(len(PHASES_S) - 1)]
    shares = ", ".join(
        f"[{lo:g}, {hi:g}) s {round(100.0 * e / sum(excess)):d} %"
        for lo, hi, e in zip(PHASES_S[:-1], PHASES_S[1:], excess, strict=True)
    )
    print(f"estimated's excess IAE over the oracle, summed over patients, by phase: {shares}")


def _times(ap: argparse.ArgumentParser, flag: str, text: str) -> list[float]:
    """Comma-separated times (s, >= 0) of ``flag``; empty text gives none."""
    try:
        times = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        ap.error(f"{flag}={text!r}: comma-separated times in s")
    if any(not (t >= 0.0) for t in times):
        ap.error(f"{flag}={text!r}: every time must be >= 0 s")
    return times


if __name__ == "__main__":
    main()
