"""LPV vs PI vs Smith on a patient model not the paper's, through the real ``pressor run``.

Each seeded patient of :mod:`pressor.hil_sim.patients.pkpd` (the ``pkpd`` patient model: two-compartment
pharmacokinetics, an effect compartment, a sigmoid Emax on MAP, a transport delay, tachyphylaxis,
a haemorrhage-like drop at 20 min and a fluid-bolus-like rise at 40 min) is played by the device
of ``tests/support/protocol_device.py`` (written from docs/PROTOCOL.md alone) on a pty, signed, in
lockstep, against a real ``pressor run --controller SPEC`` on its default schedule (a real monitor
sends no K, T, tau: the cautious start for ``lpv:cautious``, the default design; PI and Smith
schedule on nothing), or with ``--device-fit`` on the K, T, tau the device sends: each
patient's least-squares FOPDT of its 10 min open-loop step (docs/notes/estimation.md, "The frontier,
revisited"). The device announces phenylephrine at 100 µg/ml, the runtime's
defaults. Of :mod:`pressor.hil_sim` only the patient model's module is used (its world, device and paper
model are not)::

    python -m benchmarks.independent_patients                  # 10 patients x lpv:cautious, pi, smith
    python -m benchmarks.independent_patients --controller pi \\
        --controller new=out/lpv_map_controller.py --patients 3
    python -m benchmarks.independent_patients --drug norepinephrine --patients 50 \\
        --controller lpv:norepinephrine-cautious --controller pi

``--drug norepinephrine`` plays the model's one-compartment variant as a norepinephrine patient
(the patients of :class:`research.steep_patients.SteepNorepinephrine`, whose docstring gives the
sources): the device announces norepinephrine at 16 µg/ml (4 mg in 250 ml), ``pressor run`` doses
a 70 kg patient (``--drug norepinephrine --concentration-ug-ml 16 --weight-kg 70``), and the
patient counts each µg of norepinephrine as 10 µg of phenylephrine.

Per patient and controller it prints the IAE over the whole run (mmHg·s, on the true MAP), the
start step's overshoot (% of the step, before the haemorrhage), each disturbance's peak deviation
(mmHg, signed) and recovery into ±5 mmHg (s), as docs/METRICS.md defines them; then per controller
"IAE below PI's: k of N" and the median per-patient IAE ratio to the PI, and issue 41's figures
over the reachable patients (:func:`figure_lines`). Reachable: the patient's steady-state rate for
the target after the haemorrhage is within the pump's maximum. The same seed prints the same
bytes; progress and wall times go to stderr.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import statistics
import subprocess
import sys
import tempfile
import time
import tty
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from benchmarks.sweep_figures import LONG_ABOVE_S
from pressor.contracts.metrics import run_metrics
from pressor.hil_sim.patients.pkpd import (
    BOLUS_AT_S,
    HEMORRHAGE_AT_S,
    IndependentPatient,
    PatientParams,
    draw_patient,
)
from research.steep_patients import NOREPINEPHRINE_UG_ML, PHENYLEPHRINE_UG_PER_NOREPINEPHRINE_UG
from research.step_fit import step_response_fit
from tests.support.protocol_device import DeviceConfig, ProtocolDevice, build_dialect, read_key
from tests.support.protocol_harness import wait_for_port_open, write_key

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_PERIOD_S = 0.1  # 1 / pressor run's default --rate (s)
PUMP_MAX_ML_H = 120.0  # the controllers' default maximum rate (ml/h)


@dataclass(frozen=True)
class Drug:
    """The drug a benchmark's device announces, and how its patients count it.

    Attributes
    ----------
    name
        The drug the device announces and ``pressor run --drug`` loads.
    concentration_ug_ml
        The syringe (µg/ml), announced and passed as ``--concentration-ug-ml``.
    phenylephrine_ug_per_ug
        µg of phenylephrine the patient model counts for each µg of the drug (the model's
        EC50 is in ng/ml of phenylephrine).
    cohort
        The :func:`pressor.hil_sim.patients.pkpd.draw_patient` model its patients are drawn from.
    weight_kg
        The patient's weight passed as ``--weight-kg`` (kg), or None (a drug dosed per minute).
    controllers
        The controllers run when no ``--controller`` is given.
    """

    name: str
    concentration_ug_ml: float
    phenylephrine_ug_per_ug: float
    cohort: str
    weight_kg: float | None
    controllers: tuple[str, ...]

    @property
    def patient_concentration_ug_ml(self) -> float:
        """The syringe in the patient model's µg of phenylephrine per ml."""
        return self.concentration_ug_ml * self.phenylephrine_ug_per_ug

    def run_flags(self) -> list[str]:
        """``pressor run``'s flags for this drug (none for the runtime's default drug)."""
        if self.name == "phenylephrine":
            return []
        flags = ["--drug", self.name, "--concentration-ug-ml", f"{self.concentration_ug_ml:g}"]
        return flags + ([] if self.weight_kg is None else ["--weight-kg", f"{self.weight_kg:g}"])


#: the drugs a benchmark plays. Phenylephrine: the two-compartment model at the runtime's default
#: syringe. Norepinephrine: the one-compartment variant at 4 mg in 250 ml, 70 kg, each µg counted
#: as :data:`~research.steep_patients.PHENYLEPHRINE_UG_PER_NOREPINEPHRINE_UG` µg of phenylephrine.
DRUGS: dict[str, Drug] = {
    "phenylephrine": Drug(
        "phenylephrine", 100.0, 1.0, "two-compartment", None, ("lpv:cautious", "pi", "smith")
    ),
    "norepinephrine": Drug(
        "norepinephrine",
        NOREPINEPHRINE_UG_ML,
        PHENYLEPHRINE_UG_PER_NOREPINEPHRINE_UG,
        "one-compartment",
        70.0,
        ("lpv:norepinephrine-cautious", "pi", "smith"),
    ),
}


@dataclass(frozen=True)
class Setup:
    """What every run of a benchmark shares (units in the names)."""

    duration_s: float = 3600.0
    target_mmhg: float = 70.0
    noise_mmhg: float = 0.3
    #: the device sends each patient's least-squares FOPDT of its own 10 min open-loop step
    #: (:func:`research.step_fit.step_response_fit`) as SCHEDULING_PARAMS and ``pressor run``
    #: schedules on it (``--schedule oracle``): an identification made before the loop
    device_fit: bool = False
    #: the drug the device announces and the patients are dosed with (:data:`DRUGS`)
    drug: Drug = DRUGS["phenylephrine"]


def controller_label(spec: str) -> tuple[str, str]:
    """``NAME=SPEC`` -> (NAME, SPEC); a bare spec is its own name, a module path its folder's."""
    if "=" in spec:
        name, _, spec = spec.partition("=")
        return name, spec
    if spec.endswith(".py"):
        return Path(spec).resolve().parent.name, spec
    return spec, spec


def launch(
    dialect: ModuleType,
    workdir: Path,
    cfg: DeviceConfig,
    patient: IndependentPatient,
    controller: str,
    schedule: str | None = None,
    drug: Drug = DRUGS["phenylephrine"],
) -> list[float]:
    """Run ``pressor run --controller controller [--schedule schedule]`` with ``drug``'s flags on
    a fresh pty against ``patient`` (``schedule`` None: pressor run's default).

    Returns the true MAP (mmHg) at every tick; raises RuntimeError when the run did not finish
    cleanly (its stderr's tail in the message).
    """
    key_file = write_key(workdir / "signing.key")
    cfg = replace(cfg, key=read_key(key_file))
    master, slave = os.openpty()
    tty.setraw(slave)
    argv = [sys.executable, "-m", "pressor", "run", "--port", os.ttyname(slave)]
    argv += ["--signing-key", str(key_file), "--controller", controller]
    argv += [] if schedule is None else ["--schedule", schedule]
    argv += drug.run_flags()
    err = workdir / "run.err"
    with (workdir / "run.out").open("w") as fout, err.open("w") as ferr:
        proc = subprocess.Popen(
            argv, cwd=workdir, env=dict(os.environ, CI="1"), stdout=fout, stderr=ferr
        )
    try:
        os.close(slave)
        wait_for_port_open(master, proc)
        device = ProtocolDevice(
            dialect, master, cfg, peer_gone=lambda: proc.poll() is not None, patient=patient
        )
        log = device.run()
        rc = proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(master)
    if rc != 0 or log.outcome != "finished" or len(log.true_map_mmhg) != cfg.n_ticks:
        tail = err.read_text().strip().splitlines()[-3:]
        raise RuntimeError(f"pressor run --controller {controller}: rc {rc}, {log.outcome}: {tail}")
    return log.true_map_mmhg


class RecordingPatient(IndependentPatient):
    """An :class:`IndependentPatient` that keeps every delivered rate (ml/h), one per tick."""

    def __init__(self, *args: Any, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self.rates_ml_h: list[float] = []

    def step(self, rate_ml_h: float) -> None:
        """Record ``rate_ml_h`` (ml/h) and advance one sample period."""
        self.rates_ml_h.append(rate_ml_h)
        super().step(rate_ml_h)


def run_patient(
    dialect: ModuleType, params: PatientParams, controller: str, setup: Setup, seed: int
) -> dict[str, Any]:
    """One patient under one controller through ``pressor run``: the metrics of the run.

    Returns ``iae_mmhg_s``, ``step_iae_mmhg_s``, ``step_overshoot_pct``, ``disturbances``,
    ``stable`` (run_metrics of docs/METRICS.md, judged on the true MAP with the bands of a noisy
    monitor when ``setup.noise_mmhg`` > 0, as a trial judges a noisy scenario; events at
    :data:`HEMORRHAGE_AT_S` and :data:`BOLUS_AT_S` when inside the run), ``reachable`` and
    ``final_map_mmhg``.
    """
    conc = setup.drug.patient_concentration_ug_ml
    patient = RecordingPatient(params, SAMPLE_PERIOD_S, conc)
    if setup.device_fit:  # what the device sends as K, T, tau
        patient.K, patient.T_s, patient.tau_s = step_response_fit(
            params, setup.target_mmhg, SAMPLE_PERIOD_S, conc, PUMP_MAX_ML_H
        )
    n_ticks = round(setup.duration_s / SAMPLE_PERIOD_S)
    cfg = DeviceConfig(
        n_ticks=n_ticks,
        target_mmhg=setup.target_mmhg,
        send_scheduling=setup.device_fit,
        pump_max_ml_h=PUMP_MAX_ML_H,
        drug=setup.drug.name,
        concentration_ug_ml=setup.drug.concentration_ug_ml,
        noise_mmhg=setup.noise_mmhg,
        seed=seed,
        name="independent",
    )
    with tempfile.TemporaryDirectory(prefix="indep-run-") as tmp:
        schedule = "oracle" if setup.device_fit else None
        true_map = launch(dialect, Path(tmp), cfg, patient, controller, schedule, setup.drug)
    t_s = [k * SAMPLE_PERIOD_S for k in range(n_ticks)]
    need = patient.steady_state_rate_ml_h(setup.target_mmhg + params.hemorrhage_mmhg, PUMP_MAX_ML_H)
    m = run_metrics(
        t_s,
        true_map,
        setup.target_mmhg,
        patient.rates_ml_h,
        PUMP_MAX_ML_H,
        step_time_s=0.0,
        step_mmhg=setup.target_mmhg - true_map[0],
        noisy=setup.noise_mmhg > 0.0,  # the device's monitor adds noise: the 5 mmHg bands
        reachable=need is not None,
        events=[("hemorrhage", HEMORRHAGE_AT_S), ("bolus", BOLUS_AT_S)],
    )
    keep = (
        "iae_mmhg_s",
        "step_iae_mmhg_s",
        "step_overshoot_pct",
        "disturbances",
        "stable",
        "time_to_band_s",
        "time_in_band_pct",
        "longest_above_10_mmhg_s",
    )
    return {k: m[k] for k in keep} | {"reachable": need is not None, "final_map_mmhg": true_map[-1]}


def _fmt(x: float | None, spec: str) -> str:
    return "-" if x is None else format(x, spec)


def _event(kind: str, field: str) -> Callable[[dict[str, Any]], float | None]:
    return lambda rec: next((e[field] for e in rec["disturbances"] if e["kind"] == kind), None)


#: the per-patient table: header, value of a run record, format
COLUMNS: tuple[tuple[str, Callable[[dict[str, Any]], float | None], str], ...] = (
    ("IAE mmHg.s", lambda rec: rec["iae_mmhg_s"], ".0f"),
    ("step OS %", lambda rec: rec["step_overshoot_pct"], ".2f"),
    ("hem peak mmHg", _event("hemorrhage", "peak_deviation_mmhg"), ".2f"),
    ("hem rec s", _event("hemorrhage", "recovery_s"), ".1f"),
    ("bolus peak mmHg", _event("bolus", "peak_deviation_mmhg"), ".2f"),
    ("bolus rec s", _event("bolus", "recovery_s"), ".1f"),
    ("final MAP mmHg", lambda rec: rec["final_map_mmhg"], ".1f"),
)


def print_table(name: str, spec: str, records: list[dict[str, Any]]) -> None:
    """One controller's per-patient lines."""
    print(f"\n{name} (--controller {spec})")
    print("  patient  " + "  ".join(h for h, _, _ in COLUMNS) + "  stable")
    for i, rec in enumerate(records):
        cells = [_fmt(get(rec), f).rjust(len(h)) for h, get, f in COLUMNS]
        print(f"  {i:>7}  " + "  ".join(cells) + f"  {'yes' if rec['stable'] else 'NO'}")


def _median(values: list[float]) -> float | None:
    return statistics.median(values) if values else None


#: the parts of a run the summary compares separately: label, IAE of a run record (mmHg·s)
SEGMENTS: tuple[tuple[str, Callable[[dict[str, Any]], float | None]], ...] = (
    ("step window", lambda rec: rec["step_iae_mmhg_s"]),
    ("haemorrhage", _event("hemorrhage", "iae_mmhg_s")),
    ("bolus", _event("bolus", "iae_mmhg_s")),
)


def _ratios(
    records: list[dict[str, Any]],
    ref: list[dict[str, Any]],
    iae: Callable[[dict[str, Any]], float | None],
) -> list[float]:
    """Per reachable patient, the IAE ratio record/reference (where both have the IAE)."""
    return [
        iae(a) / iae(b)  # type: ignore[operator]
        for a, b in zip(records, ref, strict=True)
        if a["reachable"] and iae(a) is not None and iae(b)
    ]


def summary_lines(results: dict[str, list[dict[str, Any]]], reference: str = "pi") -> list[str]:
    """Per controller: "NAME IAE below PI's: k of N", the median IAE ratio NAME/PI, and the same
    median over the step window and each disturbance event alone (docs/METRICS.md)."""
    if reference not in results:
        return [f"no {reference} run: no IAE comparison"]
    ref, lines = results[reference], []
    for name, records in results.items():
        if name == reference:
            continue
        ratios = _ratios(records, ref, lambda rec: rec["iae_mmhg_s"])
        below = sum(r < 1.0 for r in ratios)
        lines.append(f"{name.upper()} IAE below PI's: {below} of {len(ratios)} reachable")
        parts = [
            f"{label} {_fmt(_median(_ratios(records, ref, iae)), '.3f')}" for label, iae in SEGMENTS
        ]
        lines.append(
            f"median IAE ratio {name}/{reference}: {_fmt(_median(ratios), '.3f')}"
            f" ({', '.join(parts)})"
        )
    return lines


def figure_lines(results: dict[str, list[dict[str, Any]]], duration_s: float) -> list[str]:
    """Per controller, over its reachable patients, issue 41's figures: step overshoot (% of the
    step) median / p90 / max, patients above target + 10 mmHg for longer than
    :data:`~benchmarks.sweep_figures.LONG_ABOVE_S`, time to ±5
    mmHg (min; a patient that never gets there counts as ``duration_s``) median / p90, time in
    ±5 mmHg after the first entry (%, median), and the stability rule's flags."""
    lines = []
    for name, records in results.items():
        reach = [r for r in records if r["reachable"]]
        if not reach:
            lines.append(f"{name}: no reachable patient")
            continue
        over = [r["step_overshoot_pct"] or 0.0 for r in reach]
        to_band = [
            (duration_s if r["time_to_band_s"] is None else r["time_to_band_s"]) / 60.0
            for r in reach
        ]
        in_band = [r["time_in_band_pct"] for r in reach if r["time_in_band_pct"] is not None]
        above = sum(r["longest_above_10_mmhg_s"] > LONG_ABOVE_S for r in reach)
        lines.append(
            f"{name}: {len(reach)} reachable; overshoot % median / p90 / max"
            f" {np.median(over):.1f} / {np.percentile(over, 90):.1f} / {max(over):.1f};"
            f" > 30 s above +10 mmHg {above}; to ±5 mmHg min median / p90"
            f" {np.median(to_band):.1f} / {np.percentile(to_band, 90):.1f};"
            f" in ±5 after entry % median {_fmt(_median(in_band), '.1f')};"
            f" flagged unstable {sum(not r['stable'] for r in reach)}"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--patients", type=int, default=10, help="number of patients (default 10)")
    p.add_argument("--seed", type=int, default=2026, help="cohort seed (default 2026)")
    p.add_argument(
        "--controller",
        action="append",
        metavar="[NAME=]SPEC",
        help="a pressor run --controller spec (lpv, pi, smith[:LAMBDA_S], or a generated .py), "
        "repeatable; NAME labels it (default: a module's folder name) (default: "
        + "; ".join(f"{d.name}: {', '.join(d.controllers)}" for d in DRUGS.values())
        + ")",
    )
    p.add_argument(
        "--drug",
        choices=tuple(DRUGS),
        default="phenylephrine",
        help="the drug the device announces: phenylephrine (the two-compartment model, 100 ug/ml)"
        " or norepinephrine (the one-compartment variant, 16 ug/ml, 70 kg; the module docstring)"
        " (default: phenylephrine)",
    )
    p.add_argument(
        "--duration-s",
        type=float,
        default=Setup.duration_s,
        help="simulated time per run (s, default 3600)",
    )
    p.add_argument(
        "--target-mmhg", type=float, default=Setup.target_mmhg, help="MAP target (mmHg, default 70)"
    )
    p.add_argument(
        "--noise-mmhg",
        type=float,
        default=Setup.noise_mmhg,
        help="monitor noise std (mmHg, default 0.3)",
    )
    p.add_argument(
        "--device-fit",
        action="store_true",
        help="the device sends each patient's least-squares FOPDT of its 10 min open-loop step as"
        " SCHEDULING_PARAMS and pressor run schedules on it (--schedule oracle) (default: off,"
        " pressor run's default schedule)",
    )
    args = p.parse_args(argv)
    drug = DRUGS[args.drug]
    setup = Setup(args.duration_s, args.target_mmhg, args.noise_mmhg, args.device_fit, drug)
    controllers = [controller_label(s) for s in args.controller or drug.controllers]
    cohort = [draw_patient(args.seed, i, drug.cohort) for i in range(args.patients)]
    print(
        f"independent patients: {args.patients}, seed {args.seed}, {setup.duration_s:g} s each, "
        f"target {setup.target_mmhg:g} mmHg, monitor noise {setup.noise_mmhg:g} mmHg, "
        f"{drug.name} {drug.concentration_ug_ml:g} ug/ml ({drug.cohort} patients), "
        f"pump max {PUMP_MAX_ML_H:g} ml/h; "
        f"haemorrhage at {HEMORRHAGE_AT_S:g} s, bolus at {BOLUS_AT_S:g} s; schedule "
        + (
            "the device's step-response fit (oracle)"
            if setup.device_fit
            else "pressor run's default"
        )
    )
    print(
        "  patient  baseline mmHg  delay s  hem mmHg  bolus mmHg  steady ml/h at target, after hem"
    )
    for i, params in enumerate(cohort):
        pt = IndependentPatient(params, SAMPLE_PERIOD_S, drug.patient_concentration_ug_ml)
        need = pt.steady_state_rate_ml_h(setup.target_mmhg, PUMP_MAX_ML_H)
        need_hem = pt.steady_state_rate_ml_h(
            setup.target_mmhg + params.hemorrhage_mmhg, PUMP_MAX_ML_H
        )
        print(
            f"  {i:>7}  {params.baseline_mmhg:13.1f}  {params.delay_s:7.1f}"
            f"  {params.hemorrhage_mmhg:8.1f}  {params.bolus_mmhg:10.1f}"
            f"  {_fmt(need, '.1f'):>21}, {_fmt(need_hem, '.1f')}"
        )
    with tempfile.TemporaryDirectory(prefix="indep-dialect-") as tmp:
        with contextlib.redirect_stdout(io.StringIO()):  # mavgen narrates on stdout
            dialect = build_dialect(ROOT / "link" / "pressor.xml", Path(tmp))
    results: dict[str, list[dict[str, Any]]] = {name: [] for name, _ in controllers}
    total, done = len(cohort) * len(controllers), 0
    for i, params in enumerate(cohort):
        for name, spec in controllers:
            started = time.monotonic()
            rec = run_patient(dialect, params, spec, setup, seed=args.seed * 1000 + i)
            results[name].append(rec)
            done += 1
            print(
                f"[{done}/{total}] patient {i} {name}: IAE {rec['iae_mmhg_s']:.0f} mmHg.s "
                f"({time.monotonic() - started:.1f} s wall)",
                file=sys.stderr,
                flush=True,
            )
    for name, spec in controllers:
        print_table(name, spec, results[name])
    print("\nsummary")
    for line in summary_lines(results):
        print(f"  {line}")
    print("\nfigures (reachable patients)")
    for line in figure_lines(results, setup.duration_s):
        print(f"  {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
