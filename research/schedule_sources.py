"""Scheduling sources on patients outside the FOPDT class, in-process: is adaptation worth it?

Usage::

    python -m research.schedule_sources                          # both models, 10 patients
    python -m research.schedule_sources --model one-compartment --patients 20 --seed 7

Each seeded patient of :mod:`pressor.hil_sim.patients.pkpd` (``--model two-compartment``:
the benchmark's own pharmacology with its haemorrhage and bolus, target 70 mmHg, 60 min;
``--model one-compartment``: one-compartment kinetics, a Hill effect, no tolerance, a wide
spread, a +15 mmHg step over the patient's baseline, 30 min, no disturbance) runs through the
runtime's own closed-loop core (:class:`pressor.runtime.core.closed_loop.ClosedLoopCore`: supervisor,
scheduling source, controller), in process, without a link: a 0.3 mmHg Gaussian monitor at 10 Hz
(seeded) and a pump that delivers the command within [0, 120] ml/h. Runs per patient: the LPV with
the ``nominal``, the ``estimated`` (the default of ``pressor run``) and the opt-in ``validated``
schedule, the PI, and the Smith predictor on ``estimated`` and on ``validated``.

Experiments, run when named in ``--runs``:

* ``lpv-fit-hold`` / ``lpv-fit-slew`` (:class:`research.schedule_experiments.LimitedFit`);
* ``lpv-truth``, each patient's apparent FOPDT (:func:`research.step_fit.apparent_fopdt`)
  clamped to the controller's box;
* ``lpv-stepfit``, each patient's least-squares FOPDT of a 10 min open-loop step
  (:mod:`research.step_fit`: the higher-order lags in τ), clamped to the box alike; the ideal
  device's, at the rate that holds the target and noise-free. ``lpv-stepfit-device[:k=K]`` is a
  realistic device's: the step at (target − baseline) / K ml/h (default K the nominal 0.55, so
  the rate a device can choose without knowing the patient), the monitor's 0.3 mmHg noise;
  ``lpv-stepfit-secant[:rate=R]`` that fit with its K moved at R per s (default 5e-5) toward the
  secant gain the settled loop measures (:class:`research.fit_schedules.SecantK`);
  ``lpv-stepfit-inc`` the same with K the patient's incremental sensitivity at the target
  (:func:`research.step_fit.incremental_gain`); ``lpv-stepfit-twok:switch=S:rate=R`` the fit's K until S s, then
  towards the incremental one at R per s (:class:`research.fit_schedules.KHandover`);
* ``lpv-gate-early``, ``lpv-gate-late``, ``lpv-gate-revoke``, ``lpv-gate-kstart``
  (:class:`research.schedule_experiments.GatedFit`: the fit's schedule only while its held-out
  predictions beat the nominal model's; ``lpv-gate:key=value:...`` any other setting of it);
* ``lpv-batchfit:start=K/T/tau:decide=S`` (:class:`research.schedule_experiments.BatchFit`: the
  start schedule for S s, then one batch least-squares fit of the closed-loop data, held);
* ``lpv-estwide:start=K/T/tau:tau_prior=MODE/STD:caution=Z`` (the ``estimated`` source with its
  delay range, prior and box those of the ``--lpv`` design);
* ``lpv-onset:short=SOURCE|K/T/tau:long=K/T/tau:by=S:rise=MMHG[:start=K/T/tau]``
  (:class:`research.schedule_experiments.OnsetSwitch`: ``short`` for good if the MAP rises
  ``rise`` mmHg within ``by`` s of the infusion's start, else the fixed long-delay ``long``).

Figures in ``docs/notes/estimation.md`` ("The frontier on patients outside the model class", "A held-out
gate on the fit", "The frontier, revisited", "The start schedule decides before any data", "A
realistic device's fit, and the loop gain"). ``--lpv PATH`` runs every LPV label on another
generated module (a design with a wider box or another prefilter, ``research/designs/``);
``--json PATH`` also writes the per-patient figures.

Printed per run: IAE (mmHg·s, true MAP), step overshoot (% of the step), time in ±5 mmHg after
arrival (%), SCHED_RATE / SCHED_OUT_OF_BOX ticks, HOLD or FAILSAFE ticks; then per model the
summary figures (LPV/PI, LPV/Smith, validated/nominal medians over reachable patients, overshoot
median and p90, reachable patients the run's stability check calls unstable (docs/METRICS.md,
``stable``: the error swings across the band twice in the last quarter); on the two-compartment
model also the ratio of the IAE before the haemorrhage, the target step's share). ``pressor run``
over a pty (``benchmarks/independent_patients.py``) is the reference for the two-compartment
model; this harness is for sweeps (about 3 s per run).
"""

from __future__ import annotations

import argparse
import math
import random
import statistics
import sys
from typing import Any

from pressor.contracts.metrics import run_metrics
from pressor.hil_sim.patients.pkpd import (
    BOLUS_AT_S,
    HEMORRHAGE_AT_S,
    IndependentPatient,
    draw_patient,
)
from pressor.link import PumpStatus, TickInputs
from pressor.runtime.core.closed_loop import CLEAN_LINK, ClosedLoopCore
from pressor.runtime.core.supervisor import Supervisor
from pressor.runtime.core.supervisor_config import Fault, State, supervisor_config_for
from pressor.runtime.inputs.controller_loader import load_controller
from research.schedule_labels import (
    DEFAULT_RUNS,
    NOISE_MMHG,
    PARAMETRISED,
    RUNS,
    VARIANT,
    make_source,
    scheduled_values,
)
from research.step_fit import CONCENTRATION_UG_ML, PUMP_MAX_ML_H
from research.step_fit import STEP_S as TS_S


def _kwargs(text: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in filter(None, text.split(";")):
        key, _, value = item.partition("=")
        out[key] = eval(value, {})  # a benchmark's own command line (tuples, floats)
    return out


def run_one(
    patient: IndependentPatient, spec: str, source: str, target_mmhg: float, duration_s: float,
    seed: int, events: list[tuple[str, float]], truth: tuple[float, ...] = (),
) -> dict[str, Any]:  # fmt: skip
    """One closed-loop run in process; the run's metrics and its supervisor counts (``truth``:
    the values :func:`research.schedule_labels.scheduled_values` gives for ``source``)."""
    controller = load_controller(spec, TS_S, allow_uncertified=True)
    supervisor = Supervisor(supervisor_config_for(controller, NOISE_MMHG))
    core = ClosedLoopCore(controller, supervisor, make_source(source, controller, truth))
    rng = random.Random(seed)
    n = round(duration_s / TS_S)
    true_map, rates, k_sched = [0.0] * n, [0.0] * n, [0.0] * n
    counts = {"SCHED_RATE": 0, "SCHED_OUT_OF_BOX": 0, "HOLD/FAILSAFE": 0}
    status: PumpStatus | None = None
    volume = 0.0
    nan = math.nan
    for k in range(n):
        y = patient.map_mmhg
        true_map[k] = y
        inp = TickInputs(k, k * TS_S, y + rng.gauss(0.0, NOISE_MMHG), 0, target_mmhg, nan, nan,
                         nan, False, -1, k)  # fmt: skip
        rec = core.step(inp, k * TS_S, status, CLEAN_LINK)
        faults = rec.supervisor.faults
        counts["SCHED_RATE"] += bool(faults & Fault.SCHED_RATE)
        counts["SCHED_OUT_OF_BOX"] += bool(faults & Fault.SCHED_OUT_OF_BOX)
        counts["HOLD/FAILSAFE"] += rec.supervisor.state in (State.HOLD, State.FAILSAFE)
        k_sched[k] = rec.schedule.K
        rate = min(max(rec.command_ml_h, 0.0), PUMP_MAX_ML_H)
        rates[k] = rate
        patient.step(rate)
        volume += rate * TS_S / 3600.0
        status = PumpStatus(k + 1, rate, volume, 0)
    t_s = [k * TS_S for k in range(n)]
    m = run_metrics(t_s, true_map, target_mmhg, rates, PUMP_MAX_ML_H, step_time_s=0.0,
                    step_mmhg=target_mmhg - true_map[0], events=events)  # fmt: skip
    n_step = round(min((t for _, t in events), default=duration_s) / TS_S)
    return {
        "iae": m["iae_mmhg_s"],
        # the IAE before the first disturbance: the target step's share
        "iae_step": sum(abs(target_mmhg - y) for y in true_map[:n_step]) * TS_S,
        "os": m["step_overshoot_pct"] or 0.0,
        "band": m["time_in_band_pct"],
        "stable": m["stable"],
        "K_end": k_sched[-1],
    } | counts


def run_project(scenario: Any, spec: str, source: str, patient_seed: int) -> dict[str, Any]:
    """One patient of the project's own cohort (:mod:`pressor.hil_sim`) through the trial's closed loop."""
    import pressor.hil_sim.trials.trial as trial

    trial.make_schedule = lambda name, ts: make_source(name)  # type: ignore[assignment]
    if source.startswith("stepfit"):
        raise ValueError(
            f"{source} runs on the independent models only (the cohort has the oracle)"
        )
    source = "oracle" if source == "truth" else source  # the cohort's truth is the device's
    rec, traj = trial._simulate_patient(scenario, spec, patient_seed, TS_S, source)
    faults = traj.faults
    return {
        "iae": rec["iae_mmhg_s"],
        "os": rec["step_overshoot_pct"] or 0.0,
        "band": rec["time_in_band_pct"],
        "stable": rec["stable"],
        "K_end": float(traj.sched_K[-1]),
        "reachable": rec["reachable"],
        "SCHED_RATE": int(((faults & int(Fault.SCHED_RATE)) != 0).sum()),
        "SCHED_OUT_OF_BOX": int(((faults & int(Fault.SCHED_OUT_OF_BOX)) != 0).sum()),
        "HOLD/FAILSAFE": int(((traj.state == State.HOLD) | (traj.state == State.FAILSAFE)).sum()),
    }


def cohort(model: str, seed: int, n: int) -> list[tuple[IndependentPatient, float, float, list]]:
    """(fresh-patient factory args) per patient: patient, target mmHg, duration s, events."""
    out = []
    for i in range(n):
        params = draw_patient(seed, i, model)
        if model == "two-compartment":
            p = IndependentPatient(params, TS_S, CONCENTRATION_UG_ML)
            events = [("hemorrhage", HEMORRHAGE_AT_S), ("bolus", BOLUS_AT_S)]
            need = p.steady_state_rate_ml_h(70.0 + params.hemorrhage_mmhg, PUMP_MAX_ML_H)
            out.append((params, 70.0, 3600.0, events, need is not None))
        else:
            p = IndependentPatient(params, TS_S, CONCENTRATION_UG_ML, disturbances=False)
            target = params.baseline_mmhg + 15.0
            need = p.steady_state_rate_ml_h(target, PUMP_MAX_ML_H)
            out.append((params, target, 1800.0, [], need is not None))
    return out


def _q(values: list[float], q: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, max(0, math.ceil(q * len(s)) - 1))]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--model", choices=("two-compartment", "one-compartment", "both"),
                   default="both")  # fmt: skip
    p.add_argument("--scenario", default="", help="the project's cohort in this scenario instead")
    p.add_argument("--patients", type=int, default=10)
    p.add_argument("--seed", type=int, default=2026)
    p.add_argument(
        "--runs",
        default=",".join(DEFAULT_RUNS),
        help=f"comma-separated of {', '.join(RUNS)} (default: {','.join(DEFAULT_RUNS)})",
    )
    p.add_argument("--json", default="", help="also write the per-patient results to this file")
    p.add_argument("--sched", default="", help="ValidatedSchedule kwargs: key=value;...")
    p.add_argument("--bank", default="", help="ModelBank kwargs: key=value;...")
    p.add_argument(
        "--lpv",
        default="lpv",
        help="the LPV labels' controller: lpv or a generated module's path (default: lpv)",
    )
    args = p.parse_args(argv)
    VARIANT["sched"], VARIANT["bank"] = _kwargs(args.sched), _kwargs(args.bank)
    labels = args.runs.split(",")
    for lab in labels:
        if lab.startswith("fixed:"):
            RUNS[lab] = ("lpv", lab)
        if lab.startswith(PARAMETRISED):
            RUNS[lab] = ("lpv", lab[4:])
    for lab, (spec, src) in RUNS.items():
        if spec == "lpv":
            RUNS[lab] = (args.lpv, src)
    models = ("two-compartment", "one-compartment") if args.model == "both" else (args.model,)
    if args.scenario:
        from pressor.hil_sim.patients.cohort import cohort_seeds
        from pressor.hil_sim.scenarios.scenario import load_scenario

        scenario = load_scenario(args.scenario)
        seeds = cohort_seeds(args.seed, args.patients)
        models = (f"project cohort, {args.scenario}",)
    for model in models:
        print(f"\n{model}: {args.patients} patients, seed {args.seed}")
        res: dict[str, list[dict[str, Any]]] = {lab: [] for lab in labels}
        reach = []
        plan = (
            [(None, 0.0, 0.0, [], True)] * args.patients
            if args.scenario
            else cohort(model, args.seed, args.patients)
        )
        for i, (params, target, dur, events, ok) in enumerate(plan):
            line = [f"  {i:>2}"]
            for lab in labels:
                spec, src = RUNS[lab]
                if args.scenario:
                    r = run_project(scenario, spec, src, seeds[i])
                    ok = r["reachable"]
                else:
                    disturb = model == "two-compartment"
                    pt = IndependentPatient(params, TS_S, CONCENTRATION_UG_ML, disturbances=disturb)
                    truth = scheduled_values(src, params, target, args.seed * 1000 + i)
                    r = run_one(pt, spec, src, target, dur, args.seed * 1000 + i, events, truth)
                res[lab].append(r)
                line.append(
                    f"{lab} {r['iae']:6.0f} os {r['os']:5.1f} band {r['band'] or 0:5.1f}"
                    f" rate {r['SCHED_RATE']:4d} box {r['SCHED_OUT_OF_BOX']:5d}"
                    f" hold {r['HOLD/FAILSAFE']} K {r['K_end']:.2f}"
                )
            reach.append(ok)
            line[0] += " R" if ok else " -"
            print(" | ".join(line), flush=True)
        idx = [i for i, ok in enumerate(reach) if ok]
        print(f"  reachable: {len(idx)} of {len(reach)}")
        if args.json:
            import json

            with open(args.json, "w") as fh:
                json.dump({"reach": reach, "res": res}, fh)

        def ratio(a: str, b: str, res: Any = res, idx: list[int] = idx) -> list[float]:
            return [res[a][i]["iae"] / res[b][i]["iae"] for i in idx]

        for lab in labels:
            os_ = [res[lab][i]["os"] for i in idx]
            band = [res[lab][i]["band"] or 0.0 for i in idx]
            print(
                f"  {lab:14s} overshoot median {statistics.median(os_):5.1f} %, p90"
                f" {_q(os_, 0.9):5.1f} %; band median {statistics.median(band):5.1f} % (min"
                f" {min(band):5.1f}); SCHED_RATE total {sum(r['SCHED_RATE'] for r in res[lab])};"
                f" HOLD/FAILSAFE total {sum(r['HOLD/FAILSAFE'] for r in res[lab])};"
                f" unstable {sum(not res[lab][i]['stable'] for i in idx)}"
            )
        for a, b in (("lpv-validated", "pi"), ("lpv-nominal", "pi"), ("lpv-estimated", "pi"),
                     ("lpv-truth", "pi"), ("lpv-truth", "smith"), ("lpv-truth", "lpv-nominal"),
                     ("lpv-stepfit", "pi"), ("lpv-stepfit", "smith"),
                     ("lpv-validated", "smith-validated"), ("lpv-validated", "lpv-nominal"),
                     ("lpv-estimated", "lpv-nominal"),
                     *((lab, ref) for lab in labels if lab.startswith(("lpv-gate", "lpv-batchfit", "lpv-estwide", "lpv-stepfit-", "lpv-onset", "fixed:"))
                       for ref in ("lpv-nominal", "pi", "smith"))):  # fmt: skip
            if a in res and b in res:
                r = ratio(a, b)
                step = ""
                if model == "two-compartment":  # the target step before the disturbances
                    rs = [res[a][i]["iae_step"] / res[b][i]["iae_step"] for i in idx]
                    step = f"; before the haemorrhage median {statistics.median(rs):.3f}"
                print(
                    f"  {a}/{b}: median {statistics.median(r):.3f}, max {max(r):.3f},"
                    f" below 1 on {sum(x < 1.0 for x in r)} of {len(r)}{step}"
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
