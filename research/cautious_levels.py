"""What the cautious start measures at each drug-sensitivity level, against the PI.

Usage::

    python -m research.cautious_levels --controller lpv:cautious --schedule cautious --patients 20 --seed 3
    python -m research.cautious_levels --controller lpv:norepinephrine-cautious --schedule cautious \\
        --patient-model norepinephrine --levels 0.5,1,2
    python -m research.cautious_levels --controller lpv:cautious --patient-model pkpd --levels 1,10 \\
        --caution 'phenylephrine:{"start_margin": 2, "T_s": 300, "effect_lag_s": null}'

Every patient of the cohort ``(--seed, --patients)`` runs ``--scenario`` (default
``paper-disturbance``) at each sensitivity level (:mod:`pressor.hil_sim.patients.sensitivity`) under the
controller and under the PI (the reference of the IAE ratio), through :func:`pressor.api.trial`
(the code path of ``pressor trial``). Printed per level, a Markdown row:

- ``reach``: patients whose step the pump can hold (the model's ``max_delta_map_mmhg`` at the
  level is at least the step); the figures below are over them;
- ``overshoot p50/p90/max``: step overshoot in % of the step (the records' ``step_overshoot_pct``:
  largest excess of MAP over the target before the first disturbance);
- ``above+10``: patients whose MAP stayed above target + 10 mmHg for longer than 30 s at a time
  before the first disturbance;
- ``to ±5 p50/p90``: time (min) from the step to the first 1 Hz sample within ±5 mmHg of the
  target (true MAP); a patient that never gets there counts as the scenario's duration;
- the same for the PI, and ``IAE ÷ PI``: the median over patients of the ratio of whole-run IAE;
- ``unstable``: records whose ``stable`` flag is false (docs/METRICS.md), controller / PI.

This is the measurement script of the cautious-start work (docs/notes/cautious-start.md); the
sweep of record is :mod:`benchmarks.sensitivity_sweep`.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from pressor.contracts.drug import DoseScale
from pressor.runtime.estimation import cautious
from pressor.runtime.estimation.caution import CAUTION_FOR_DRUG, Caution
from pressor.runtime.estimation.design_envelope import DesignEnvelope

LEVELS = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0)


def use_cautious_source(cls: type[cautious.CautiousSchedule], **settings: Any) -> None:
    """Make ``--schedule cautious`` build ``cls(envelope, sample_period_s, dose, **settings)`` in
    this process and in the workers forked from it (the source is looked up in its module at
    each run): how a research variant of the cautious source is measured with :func:`main`."""

    class _Installed(cls):  # type: ignore[valid-type, misc]
        def __init__(
            self,
            envelope: DesignEnvelope,
            sample_period_s: float = 0.1,
            dose: DoseScale | None = None,
        ) -> None:
            super().__init__(envelope, sample_period_s, dose, **settings)

    cautious.CautiousSchedule = _Installed  # type: ignore[misc]


def replace_caution(spec: str) -> None:
    """Replace a drug's caution in this process and the workers forked from it: ``spec`` is
    ``DRUG:JSON``, the JSON the fields of :class:`~pressor.runtime.estimation.caution.Caution`."""
    drug, _, fields = spec.partition(":")
    CAUTION_FOR_DRUG[drug] = Caution(**json.loads(fields))


def _first_entry_min(t_s: np.ndarray, mapv: np.ndarray, target: np.ndarray, t0: float) -> float:
    """Minutes from ``t0`` to the first sample within ±5 mmHg of the target (inf if none)."""
    ok = (t_s >= t0) & (np.abs(mapv - target) <= 5.0)
    idx = np.flatnonzero(ok)
    return float((t_s[idx[0]] - t0) / 60.0) if idx.size else float("inf")


def _in_band_after_entry(t_s: np.ndarray, mapv: np.ndarray, target: np.ndarray, t0: float) -> float:
    """% of the 1 Hz samples within ±5 mmHg of the target from the first entry on (0 if none)."""
    ok = (t_s >= t0) & (np.abs(mapv - target) <= 5.0)
    idx = np.flatnonzero(ok)
    if not idx.size:
        return 0.0
    return float(100.0 * np.mean(ok[idx[0] :]))


def _longest_above_s(t_s: np.ndarray, mapv: np.ndarray, target: np.ndarray, t_end: float) -> float:
    """Longest run (s) of 1 Hz samples with MAP above target + 10 mmHg before ``t_end``."""
    above = (mapv > target + 10.0) & (t_s < t_end)
    best = run = 0
    for a in above:
        run = run + 1 if a else 0
        best = max(best, run)
    return float(best)


def run_level(
    controller: str,
    schedule: str,
    level: float,
    n: int,
    seed: int,
    scenario: str,
    model: str,
    jobs: int,
) -> list[dict[str, Any]]:
    """One trial at ``level``: per patient the figures of the module docstring."""
    from pressor import api
    from pressor.hil_sim.scenarios.scenario import load_scenario

    sc = load_scenario(scenario)
    step = sc.step_mmhg
    t0 = sc.step_time_s
    dist = [d.start_s for d in sc.disturbances] or [sc.duration_s]
    t_end = min(dist)
    res = api.trial(
        controller,
        scenario,
        n,
        seed,
        jobs=jobs,
        schedule=schedule,
        patient_model=model,
        sensitivity=level,
        trajectories=True,
    )
    tr = res.trajectories
    out = []
    for i, rec in enumerate(res.records):
        t_s, mp, tg = tr["t_s"], tr["map_true_mmhg"][i], tr["target_mmhg"][i]
        out.append(
            {
                "seed": rec["patient_seed"],
                "reach_step": bool(rec.get("max_delta_mmhg", np.inf) >= step),
                "overshoot_pct": rec.get("step_overshoot_pct") or 0.0,
                "above10_s": _longest_above_s(t_s, mp, tg, t_end),
                "to_band_min": min(_first_entry_min(t_s, mp, tg, t0), sc.duration_s / 60.0),
                "iae": rec["iae_mmhg_s"],
                "in_band_pct": _in_band_after_entry(t_s, mp, tg, t0),
                "max_above_mmhg": float(np.max(mp[t_s >= t0] - tg[t_s >= t0])),
                "stable": bool(rec["stable"]),
            }
        )
    return out


def _pct(v: list[float], q: float) -> float:
    return float(np.percentile(v, q)) if v else float("nan")


def row(level: float, lpv: list[dict[str, Any]], pi: list[dict[str, Any]]) -> str:
    """One Markdown row for ``level`` (see the module docstring)."""
    idx = [i for i, r in enumerate(lpv) if r["reach_step"]]
    ov = [lpv[i]["overshoot_pct"] for i in idx]
    tb = [lpv[i]["to_band_min"] for i in idx]
    tbp = [pi[i]["to_band_min"] for i in idx]
    ratio = [lpv[i]["iae"] / pi[i]["iae"] for i in idx if pi[i]["iae"] > 0]
    above = sum(1 for i in idx if lpv[i]["above10_s"] > 30.0)
    unst = sum(1 for r in lpv if not r["stable"])
    unst_pi = sum(1 for r in pi if not r["stable"])
    band = [lpv[i]["in_band_pct"] for i in idx]
    above_run = [lpv[i]["max_above_mmhg"] for i in idx]
    return (
        f"| {level:g}× | {len(idx)}/{len(lpv)} | {_pct(ov, 50):.1f} / {_pct(ov, 90):.1f} / "
        f"{max(ov, default=float('nan')):.1f} | {above} | {_pct(tb, 50):.1f} / {_pct(tb, 90):.1f} | "
        f"{_pct(tbp, 50):.1f} / {_pct(tbp, 90):.1f} | {_pct(ratio, 50):.2f} | {_pct(band, 50):.1f} | {_pct(above_run, 90):.1f} | {unst} / {unst_pi} |"
    )


HEADER = (
    "| level | reach | overshoot % p50 / p90 / max | above+10 > 30 s | to ±5 min p50 / p90 |"
    " PI to ±5 p50 / p90 | IAE ÷ PI (median) | in ±5 after entry % | max above target, run, p90 mmHg |"
    " unstable / PI |\n"
    "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--controller", default="lpv")
    p.add_argument("--schedule", default="cautious")
    p.add_argument("--baseline", default="pi")
    p.add_argument("--levels", default=",".join(f"{x:g}" for x in LEVELS))
    p.add_argument("--patients", type=int, default=20)
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--scenario", default="paper-disturbance")
    p.add_argument("--patient-model", default="paper")
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--cache", type=Path, default=None, help="directory caching the baseline runs")
    p.add_argument(
        "--caution",
        action="append",
        default=[],
        metavar="DRUG:JSON",
        help="replace a drug's caution for this run (workers forked from here see it), e.g."
        """ 'phenylephrine:{"start_margin": 1, "T_s": 200, "effect_lag_s": null}'"""
        " (runtime/estimation/caution.py, Caution; default: the shipped CAUTION_FOR_DRUG)",
    )
    a = p.parse_args(argv)
    for spec in a.caution:
        replace_caution(spec)
    levels = [float(x) for x in a.levels.split(",")]
    print(
        f"controller {a.controller} ({a.schedule}) vs {a.baseline}; {a.scenario}, "
        f"{a.patient_model}, {a.patients} patients, seed {a.seed}"
    )
    print(HEADER)
    for lv in levels:
        t = time.time()
        key = f"{a.baseline}-{a.scenario}-{a.patient_model}-{a.patients}-{a.seed}-{lv:g}.json"
        cached = a.cache / key if a.cache else None
        if cached is not None and cached.exists():
            pi = json.loads(cached.read_text())
        else:
            pi = run_level(
                a.baseline, "oracle", lv, a.patients, a.seed, a.scenario, a.patient_model, a.jobs
            )
            if cached is not None:
                cached.parent.mkdir(parents=True, exist_ok=True)
                cached.write_text(json.dumps(pi))
        lpv = run_level(
            a.controller, a.schedule, lv, a.patients, a.seed, a.scenario, a.patient_model, a.jobs
        )
        print(row(lv, lpv, pi), flush=True)
        print(f"  ({time.time() - t:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
