"""Cost and accuracy of the online K, T, τ estimator (pressor.runtime.estimation), in shadow mode.

Usage::

    python -m benchmarks.estimator                          # 100 patients, seed 2026, LPV, 2 jobs
    python -m benchmarks.estimator --patients 20 --controller pi --jobs 1

1. Per-tick cost: :meth:`EstimatedSchedule.update` timed tick by tick over ``--cost-ticks`` ticks of
   a seeded, excited first-order-plus-delay plant (median, p99, max in µs; pure Python).
2. Accuracy on this project's simulated patients: each patient of the seeded cohort runs in
   ``paper-tracking`` and ``paper-disturbance`` under ``--controller`` scheduled on the ORACLE (as
   ``pressor trial`` does today); the estimator runs beside it in shadow mode, fed each tick the
   monitor's MAP sample and quality bits and the pump's delivered rate (PUMP_STATUS), exactly what
   the runtime receives. Per patient: median absolute error over the second half of the run against
   the world's true K, T, τ; printed: the median over patients of ``K_rel_err_pct``,
   ``T_rel_err_pct`` and ``tau_abs_err_s``, per scenario and pooled, with the issue's targets.
3. The same figures with the loop open and the rate excited (``--excited N`` patients of
   ``paper-tracking``, a seeded staircase of 10–60 ml/h held 150 s): what the estimator reaches
   when the data carry information throughout, to separate its accuracy from the closed loop's
   lack of excitation once the MAP has settled.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import random
import statistics
import time

from pressor.hil_sim.patients.cohort import cohort_seeds
from pressor.hil_sim.world import World
from pressor.runtime.core.scheduling import ScheduleInput
from pressor.runtime.estimation.sources import EstimatedSchedule
from pressor.runtime.inputs.controller_loader import load_controller

SCENARIOS = ("paper-tracking", "paper-disturbance")
TARGETS = {"K_rel_err_pct": 15.0, "T_rel_err_pct": 25.0, "tau_abs_err_s": 5.0}
TS = 0.1


def tick_cost_us(ticks: int, seed: int = 0) -> list[float]:
    """Per-tick wall time (µs) of the estimated schedule on an excited, noisy FOPDT plant."""
    rng = random.Random(seed)
    src = EstimatedSchedule(sample_period_s=TS)
    d = math.exp(-TS / 150.0)
    delay = 300  # 30 s
    rates = [0.0] * (delay + 1)
    x, rate, times = 0.0, 30.0, []
    clock = time.perf_counter_ns
    for k in range(ticks):
        if k % 1500 == 0:
            rate = rng.uniform(10.0, 60.0)
        y = 55.0 + x + rng.gauss(0.0, 0.1)
        prev = rates[(k - 1) % len(rates)]
        t0 = clock()
        src.update(ScheduleInput(y, 0, prev, math.nan, math.nan, math.nan, False))
        times.append((clock() - t0) / 1000.0)
        rates[k % len(rates)] = rate
        x = d * x + (1.0 - d) * 0.5 * rates[(k - delay) % len(rates)]
    return times


class Staircase:
    """Open-loop command: a seeded uniform 10–60 ml/h level held 150 s (the ``--excited`` runs)."""

    def __init__(self, seed: int) -> None:
        self._rng = random.Random(seed)
        self._k = 0
        self._level = 0.0

    def step(self, *_: float) -> float:
        if self._k % 1500 == 0:
            self._level = self._rng.uniform(10.0, 60.0)
        self._k += 1
        return self._level


def shadow_patient(job: tuple[str, str, int]) -> dict[str, float]:
    """One patient under the oracle-scheduled controller (or the staircase), estimator in shadow."""
    scenario, controller_spec, seed = job
    world = World(scenario, seed, TS)
    controller = (
        Staircase(seed) if controller_spec == "staircase" else load_controller(controller_spec, TS)
    )
    src = EstimatedSchedule(sample_period_s=TS)
    n = round(world.scenario.duration_s / TS)
    k_err, t_err, tau_err = [], [], []
    delivered = 0.0  # PUMP_STATUS before the first advance: nothing flowing
    prior_ticks = 0
    for k in range(n):
        obs = world.observe()
        s = src.update(obs.map_mmhg, obs.quality, delivered, obs.K, obs.T_s, obs.tau_s, True)
        u = controller.step(obs.map_mmhg, obs.target_mmhg, obs.K, obs.T_s, obs.tau_s)
        world.apply_command(u)
        delivered = world.advance().delivered_ml_h
        if 2 * k >= n:
            k_err.append(abs(s.K - obs.K) / obs.K * 100.0)
            t_err.append(abs(s.T_s - obs.T_s) / obs.T_s * 100.0)
            tau_err.append(abs(s.tau_s - obs.tau_s))
            prior_ticks += s.from_prior
    return {
        "K_rel_err_pct": statistics.median(k_err),
        "T_rel_err_pct": statistics.median(t_err),
        "tau_abs_err_s": statistics.median(tau_err),
        "prior_fraction": prior_ticks / len(k_err),
        "reachable": world.reachable(),
    }


def _summary(label: str, records: list[dict[str, float]]) -> None:
    print(f"  {label} ({len(records)} patients)")
    for name, target in TARGETS.items():
        value = statistics.median(r[name] for r in records)
        verdict = "ok" if value <= target else f"MISSED by {value - target:.3g}"
        print(f"    {name:<16} median {value:8.2f}   target <= {target:g}   {verdict}")
    prior = statistics.median(r["prior_fraction"] for r in records)
    print(f"    {'prior_fraction':<16} median {prior:8.2f}   (second-half ticks on the prior)")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--patients", type=int, default=100, help="cohort size (default 100)")
    p.add_argument("--seed", type=int, default=2026, help="cohort seed (default 2026)")
    p.add_argument("--controller", default="lpv", help="controller spec (default lpv)")
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--cost-ticks", type=int, default=200_000, help="ticks timed (default 2e5)")
    p.add_argument(
        "--excited", type=int, default=20, help="open-loop excited patients (default 20; 0: none)"
    )
    args = p.parse_args(argv)

    times = sorted(tick_cost_us(args.cost_ticks))
    n = len(times)
    print(f"per-tick cost over {n} ticks (EstimatedSchedule.update, pure Python):")
    print(
        f"  median {times[n // 2]:.1f} µs   p99 {times[min(n - 1, int(0.99 * n))]:.1f} µs"
        f"   max {times[-1]:.1f} µs   target median <= 100 µs"
    )

    seeds = cohort_seeds(args.seed, args.patients)
    print(
        f"shadow mode: controller {args.controller} on the oracle schedule, cohort seed "
        f"{args.seed}, {args.patients} patients; median over patients of the second-half median"
        " absolute errors"
    )
    t0 = time.perf_counter()
    pooled: list[dict[str, float]] = []
    with multiprocessing.Pool(args.jobs) as pool:
        for scenario in SCENARIOS:
            jobs = [(scenario, args.controller, s) for s in seeds]
            records = pool.map(shadow_patient, jobs)
            pooled += records
            _summary(scenario, records)
        _summary("both scenarios", pooled)
        if args.excited:
            jobs = [("paper-tracking", "staircase", s) for s in seeds[: args.excited]]
            print("open loop, excited (staircase 10–60 ml/h every 150 s), paper-tracking:")
            _summary("excited", pool.map(shadow_patient, jobs))
    print(f"  wall time {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
