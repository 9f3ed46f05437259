"""Responsiveness sweep: the same cohort at several drug-sensitivity levels, per controller.

Usage::

    python -m benchmarks.sensitivity_sweep                        # 250 patients, 7 levels
    python -m benchmarks.sensitivity_sweep --patients 20 --out sweep/ --jobs 2
    python -m benchmarks.sensitivity_sweep --levels 0.1,10 --controllers lpv --seed 7

Every patient of the cohort ``(--seed, --patients)`` runs the scenario (default
``paper-disturbance``) at each sensitivity level f (default 0.1, 0.2, 0.5, 1, 2, 5, 10 × the
model's, the seven responsiveness levels of published closed-loop vasopressor robustness tests)
under each controller (default ``lpv``, ``pi``, ``smith``), all on one scheduling source (default
``estimated``, the runtime's own; the PI ignores it). A level is the patient model
``MODEL@sensitivity=f`` (:mod:`pressor.hil_sim.patients.sensitivity`: the patient responds to each delivered
ml/h as the model's responds to f ml/h, so K is f × the model's); level 1 is the unwrapped model,
so its records are ``pressor trial``'s bytes. Every cohort runs through
:func:`pressor.hil_sim.trials.trial.run_cohort`, the code path of ``pressor trial`` (``--jobs`` local processes
or ``--scheduler`` a Dask cluster; the results do not depend on either), with progress on stderr.

Printed (stdout, a Markdown table as each level finishes): per level and controller one row for
the reachable patients and one for the unreachable ones (a group without a patient has no row):

- ``patients``: how many patients the row covers, ``reachable`` (the records' ``reachable``: the
  pump's maximum rate holds the target at that level to within the metrics' band, by the model's
  ``max_delta_map_mmhg``) or ``unreachable`` (the target is beyond the pump's limit);
- ``unstable``: how many of them have the records' ``stable`` flag false, the project's criterion
  (docs/METRICS.md): non-finite true MAP, or in the final quarter of the run the error swinging
  from beyond +band to beyond −band (or back) twice or more, i.e. a sustained oscillation;
- ``MDPE``, ``MDAPE``, ``wobble``: medians over the row's patients of the records' Varvel figures
  (%, over the whole period after the target step; :mod:`pressor.contracts.metrics`);
- ``in ±5``: median % of time within ±5 mmHg of the target after first arriving there (a patient
  that never arrives counts 0 %);
- ``overshoot``: median and 90th percentile of the step overshoot (% of the step, before the first
  disturbance).

With ``--out DIR`` each (level, controller) writes ``DIR/xF/CONTROLLER/`` (``patients.json``,
``patients.csv``, ``summary.json``) and a run started again skips those already written for the
same scenario, cohort, schedule and model (delete a directory to run it again).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pressor.contracts.metrics import percentile_summary
from pressor.hil_sim.patients.patient_model import DEFAULT_PATIENT_MODEL, PatientModelError
from pressor.hil_sim.patients.sensitivity import check_factor, with_sensitivity
from pressor.hil_sim.scenarios.scenario import Scenario, load_scenario
from pressor.hil_sim.trials.trial import controller_dir_name, run_cohort, write_outputs
from pressor.runtime.estimation.sources import SOURCES

#: sensitivity levels (× the model's; dimensionless)
LEVELS = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0)
CONTROLLERS = ("lpv", "pi", "smith")
#: summary.json fields that must match for a written (level, controller) to be reused
IDENTITY = ("scenario", "controller", "patient_model", "cohort_seed", "n_patients", "schedule")
HEADER = (
    "| level | controller | patients | unstable | MDPE % | MDAPE % | wobble % | in ±5 mmHg %"
    " | step overshoot % (median / p90) |\n"
    "| ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
)


def level_dir(out: Path, level: float, controller: str) -> Path:
    """Where one (level, controller) cohort is written: ``OUT/xF/CONTROLLER``."""
    return out / f"x{level:g}" / controller_dir_name(controller)


def figures(records: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """One table row's figures over ``records`` (see the module docstring).

    Returns
    -------
    dict
        ``patients``, ``unstable`` (counts); ``mdpe_pct``, ``mdape_pct``, ``wobble_pct``,
        ``time_in_band_pct``, ``overshoot_pct`` (medians over the patients, %, ``None`` without
        one) and ``overshoot_p90_pct``.
    """

    def median(key: str, none_as: float | None = None) -> float | None:
        vals = [none_as if r[key] is None else r[key] for r in records]
        return percentile_summary(vals)["median"]  # type: ignore[return-value]

    overshoot = percentile_summary(r["step_overshoot_pct"] for r in records)
    return {
        "patients": len(records),
        "unstable": sum(not r["stable"] for r in records),
        "mdpe_pct": median("mdpe_pct"),
        "mdape_pct": median("mdape_pct"),
        "wobble_pct": median("wobble_pct"),
        "time_in_band_pct": median("time_in_band_pct", none_as=0.0),
        "overshoot_pct": overshoot["median"],
        "overshoot_p90_pct": overshoot["p90"],
    }


def _num(value: float | None, digits: int = 1) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def format_row(level: float, controller: str, group: str, fig: dict[str, Any]) -> str:
    """The Markdown table row of one level, controller and group of patients (:func:`figures`)."""
    return (
        f"| {level:g}× | {controller} | {fig['patients']} {group} | {fig['unstable']}"
        f" | {_num(fig['mdpe_pct'], 2)} | {_num(fig['mdape_pct'], 2)}"
        f" | {_num(fig['wobble_pct'], 2)} | {_num(fig['time_in_band_pct'])}"
        f" | {_num(fig['overshoot_pct'])} / {_num(fig['overshoot_p90_pct'])} |"
    )


def level_rows(level: float, controller: str, records: Sequence[dict[str, Any]]) -> list[str]:
    """The rows of one level and controller: its reachable patients, then its unreachable ones
    (no row for a group without a patient)."""
    rows = []
    for group, reachable in (("reachable", True), ("unreachable", False)):
        sub = [r for r in records if r["reachable"] is reachable]
        if sub:
            rows.append(format_row(level, controller, group, figures(sub)))
    return rows


def _reuse(path: Path, expected: dict[str, Any]) -> list[dict[str, Any]] | None:
    """The records written at ``path`` by a run with the same identity, else ``None``."""
    try:
        summary = json.loads((path / "summary.json").read_text())
        records = json.loads((path / "patients.json").read_text())
    except (OSError, ValueError):
        return None
    same = all(summary.get(k) == expected.get(k) for k in IDENTITY)
    return records if same and len(records) == expected["n_patients"] else None


def run_level(
    scenario: Scenario,
    controller: str,
    level: float,
    args: argparse.Namespace,
) -> list[dict[str, Any]]:
    """The records of one (level, controller) cohort: reused from ``--out`` or run and written."""
    model = with_sensitivity(args.patient_model, level)
    out = level_dir(args.out, level, controller) if args.out else None
    if out is not None:
        expected = {  # as summary.json names them (schedule, model: absent for the defaults)
            "scenario": scenario.name,
            "controller": controller,
            "patient_model": None if model == DEFAULT_PATIENT_MODEL else model,
            "cohort_seed": args.seed,
            "n_patients": args.patients,
            "schedule": None if args.schedule == "oracle" else args.schedule,
        }
        reused = _reuse(out, expected)
        if reused is not None:
            print(f"x{level:g} {controller}: reused {out}", file=sys.stderr)
            return reused
    label = f"x{level:g} {controller}"

    def progress(done: int, total: int) -> None:
        end = "\n" if done == total else ""
        print(f"\r{label}: {done}/{total} patients", end=end, file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    records, summary, _ = run_cohort(
        scenario,
        controller,
        args.seed,
        args.patients,
        jobs=args.jobs,
        scheduler=args.scheduler,
        progress=progress,
        schedule=args.schedule,
        patient_model=model,
    )
    print(f"{label}: {time.perf_counter() - t0:.1f} s wall", file=sys.stderr, flush=True)
    if out is not None:
        write_outputs(out, records, summary)
    return records


def _levels(text: str) -> list[float]:
    try:
        levels = [check_factor(float(v), f"--levels item {v!r}") for v in text.split(",")]
    except (ValueError, PatientModelError) as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return levels


def parser() -> argparse.ArgumentParser:
    """The command line (every option's default and unit in its help)."""
    p = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], formatter_class=argparse.RawTextHelpFormatter
    )
    p.add_argument("--patients", type=int, default=250, help="cohort size (default 250)")
    p.add_argument("--seed", type=int, default=2026, help="cohort seed (default 2026)")
    p.add_argument(
        "--scenario", default="paper-disturbance", help="name or .toml (default %(default)s)"
    )
    p.add_argument(
        "--levels",
        type=_levels,
        default=list(LEVELS),
        help="sensitivity factors, comma-separated, each in [0.05, 20] (dimensionless;"
        " default 0.1,0.2,0.5,1,2,5,10)",
    )
    p.add_argument(
        "--controllers",
        default=",".join(CONTROLLERS),
        help="controller specs, comma-separated (default %(default)s)",
    )
    p.add_argument("--schedule", choices=SOURCES, default="estimated", help="(default %(default)s)")
    p.add_argument(
        "--patient-model",
        default=DEFAULT_PATIENT_MODEL,
        help="the model whose sensitivity is scaled (default %(default)s)",
    )
    p.add_argument("--jobs", type=int, default=1, help="local worker processes (default 1)")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address (default: local)")
    p.add_argument(
        "--out", type=Path, default=None, help="write and reuse results here (default: none)"
    )
    return p


def main(argv: list[str] | None = None) -> int:
    """Run the sweep and print its table; 0 on completion, 2 on a bad argument."""
    args = parser().parse_args(argv)
    controllers = [c for c in args.controllers.split(",") if c]
    try:
        scenario = load_scenario(args.scenario)
        for level in args.levels:
            with_sensitivity(args.patient_model, level)
    except ValueError as exc:
        print(f"sensitivity_sweep: {exc}", file=sys.stderr)
        return 2
    print(
        f"sensitivity sweep: scenario {scenario.name}, cohort seed {args.seed}, {args.patients}"
        f" patients per level, schedule {args.schedule}, patient model {args.patient_model}"
    )
    print(HEADER, flush=True)
    for level in args.levels:
        rows = [
            row
            for c in controllers
            for row in level_rows(level, c, run_level(scenario, c, level, args))
        ]
        print("\n".join(rows), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
