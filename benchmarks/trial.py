"""Trial throughput: simulated patient-hours per wall-clock minute per core (target >= 60).

Runs the in-process closed loop (World + the runtime's core, 10 Hz) on one core for a few patients
of a scenario and prints the figure, measured in CPU time so that other load on the machine does not
count. The LPV runs on its estimated schedule by default (how it is meant to run); every other
controller on the oracle, ``pressor trial``'s default. It says whether the compiled twins
(:mod:`pressor.hil_sim.native`) ran; ``PRESSOR_NATIVE=off`` measures the Python alone, and ``--vs-python``
measures both in the same run, each patient once with the twins and once without, alternating (a
shared host's speed drifts by ±15 % between runs; the ratio of the paired times does not).
Usage::

    python -m benchmarks.trial [--scenario paper-disturbance] [--controller pi] [--patients 5]
        [--schedule oracle|estimated|nominal|validated] [--patient-model paper] [--vs-python]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

from pressor.hil_sim.native import controller as native_controller
from pressor.hil_sim.native import estimator as native_estimator
from pressor.hil_sim.native import patient as native_patient
from pressor.hil_sim.patients.cohort import cohort_seeds
from pressor.hil_sim.patients.patient_model import DEFAULT_PATIENT_MODEL
from pressor.hil_sim.scenarios.scenario import load_scenario
from pressor.hil_sim.trials.trial import run_patient
from pressor.plumbing.native_build import NATIVE_ENV
from pressor.runtime.estimation.sources import SOURCES


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="paper-disturbance")
    p.add_argument("--controller", default="pi")
    p.add_argument("--patients", type=int, default=5)
    p.add_argument(
        "--schedule",
        choices=SOURCES,
        default=None,
        help="scheduling source (default: estimated for lpv, else oracle)",
    )
    p.add_argument("--patient-model", default=DEFAULT_PATIENT_MODEL)
    p.add_argument(
        "--vs-python",
        action="store_true",
        help="also run every patient without the compiled twins, alternating, and print the ratio",
    )
    args = p.parse_args()
    schedule = args.schedule or ("estimated" if args.controller == "lpv" else "oracle")
    scenario = load_scenario(args.scenario)
    seeds = cohort_seeds(1, args.patients)

    def run(seed: int) -> None:
        run_patient(scenario, args.controller, seed, 0.1, schedule, args.patient_model)

    if args.vs_python:
        compare(run, seeds, scenario.duration_s / 3600.0)
        return
    run(seeds[0])  # warm-up (imports, caches, compiling the twins once)
    t0 = time.process_time()
    w0 = time.perf_counter()
    for s in seeds:
        run(s)
    cpu = time.process_time() - t0
    wall = time.perf_counter() - w0
    hours = args.patients * scenario.duration_s / 3600.0
    print(
        f"scenario={scenario.name} controller={args.controller} schedule={schedule}"
        f" patient_model={args.patient_model} patients={args.patients}"
        f" simulated={hours:.2f} patient-h wall={wall:.2f} s cpu={cpu:.2f} s"
    )
    print(
        f"throughput: {hours / (cpu / 60.0):.1f} patient-hours per wall minute per core (cpu time)"
    )
    print(f"            {hours / (wall / 60.0):.1f} patient-hours per wall minute (this process)")
    twins = {"controller": native_controller.last_reason, "patient": native_patient.last_reason}
    if schedule == "estimated":  # the only source with an estimator that has a twin
        twins["estimator"] = native_estimator.last_reason
    print(
        "compiled twins: "
        + ", ".join(f"{part} {'yes' if not why else f'no ({why})'}" for part, why in twins.items())
    )


def compare(run: Callable[[int], None], seeds: list[int], hours: float) -> None:
    """Each patient (``hours`` patient-hours) with the twins and without, alternating; median
    patient-h per CPU minute."""
    rates: dict[str, list[float]] = {"auto": [], "off": []}
    for i, seed in enumerate(seeds):
        for mode in ("auto", "off") if i % 2 == 0 else ("off", "auto"):
            os.environ[NATIVE_ENV] = mode
            t0 = time.process_time()
            run(seed)
            rates[mode].append(hours / ((time.process_time() - t0) / 60.0))
    for mode, label in (("auto", "compiled twins"), ("off", "Python alone")):
        print(
            f"{label:>15}: median {statistics.median(rates[mode][1:]):.1f} patient-h per CPU minute"
        )
    pairs = [a / b for a, b in zip(rates["auto"][1:], rates["off"][1:], strict=True)]
    print(f"{'ratio':>15}: median {statistics.median(pairs):.2f} (patient by patient; the first"
          " patient is the warm-up, not counted)")  # fmt: skip


if __name__ == "__main__":
    main()
