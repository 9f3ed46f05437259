"""Cohort scale-out: patient-hours per minute per worker, local vs a Dask cluster of 1 and 2 workers.

Starts a Dask cluster on localhost (scheduler and single-threaded worker processes, no other
service needed), runs the same cohort in this process, on 1 Dask worker and on 2, checks that the
three produce the same records, and prints wall time, patient-hours per wall minute, the same per
worker, and each figure's ratio to the in-process run measured in this run. Usage::

    python -m benchmarks.trial_scaleout [--scenario paper-tracking] [--controller pi] [--patients 16]
"""

from __future__ import annotations

import argparse
import json
import time

from distributed import LocalCluster

from pressor.hil_sim.scenarios.scenario import load_scenario
from pressor.hil_sim.trials.trial import run_trial


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="paper-tracking", help="scenario (default: %(default)s)")
    p.add_argument("--controller", default="pi", help="controller spec (default: %(default)s)")
    p.add_argument("--patients", type=int, default=16, help="cohort size (default: %(default)s)")
    p.add_argument("--seed", type=int, default=1, help="cohort seed (default: %(default)s)")
    args = p.parse_args()
    scenario = load_scenario(args.scenario)
    hours = args.patients * scenario.duration_s / 3600.0

    def timed(scheduler: str | None) -> tuple[float, str]:
        w0 = time.perf_counter()
        records = run_trial(
            scenario, args.controller, args.seed, args.patients, scheduler=scheduler
        )
        return time.perf_counter() - w0, json.dumps(records)

    rows = [("in-process", 1, *timed(None))]
    for workers in (1, 2):
        with LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0"
        ) as cluster:
            timed(cluster.scheduler_address)  # warm-up: imports on the workers
            rows.append((f"dask {workers} worker(s)", workers, *timed(cluster.scheduler_address)))
    base_wall = rows[0][2]
    print(
        f"scenario={scenario.name} controller={args.controller} patients={args.patients} "
        f"simulated={hours:.2f} patient-h"
    )
    print(f"{'backend':<20} {'wall s':>8} {'pt-h/min':>9} {'per worker':>11} {'speed-up':>9}")
    for name, workers, wall, _ in rows:
        rate = hours / (wall / 60.0)
        print(f"{name:<20} {wall:8.2f} {rate:9.1f} {rate / workers:11.1f} {base_wall / wall:8.2f}x")
    same = all(r[3] == rows[0][3] for r in rows)
    print(f"records identical across backends: {same}")
    if not same:
        raise SystemExit(1)


if __name__ == "__main__":
    main()
