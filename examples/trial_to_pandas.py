"""A trial into pandas, then a plot: the notebook-style way to look at a cohort.

Runs a small ``lpv`` trial on the shipped ``paper-disturbance`` scenario through the Python API
(:mod:`pressor.api`), keeps the 1 Hz trajectories, loads the per-patient table and the
trajectories into pandas, prints the patients with the largest IAE and writes a figure of the
cohort's MAP and infusion rate (median and 10-90 % band) to ``--out`` (PNG). Each block below is
one notebook cell. Needs pandas (``pip install -e ".[pandas]"``)::

    python examples/trial_to_pandas.py --patients 10 --out cohort.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; drop this line in a notebook
import matplotlib.pyplot as plt  # noqa: E402

from pressor import api  # noqa: E402


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--patients", type=int, default=10)
    p.add_argument("--duration-s", type=float, default=None)
    p.add_argument("--out", type=Path, default=Path("cohort.png"))
    args = p.parse_args(argv)

    # --- cell 1: run the trial (same records as `pressor trial --controller lpv ...`)
    result = api.trial(
        "lpv",
        "paper-disturbance",
        n_patients=args.patients,
        seed=1,
        duration_s=args.duration_s,
        trajectories=True,
    )

    # --- cell 2: one row per patient, the columns of patients.csv
    patients = result.to_pandas()
    worst = patients.sort_values("iae_mmhg_s", ascending=False).head(3)
    print(worst[["patient_seed", "iae_mmhg_s", "time_in_band_pct", "drug_total_ml"]])

    # --- cell 3: the trajectories, long form (patient_seed, t_s, MAP, target, rate)
    traces = result.to_pandas(trajectories=True)
    by_time = traces.groupby("t_s")
    band = by_time[["map_true_mmhg", "rate_ml_h"]].quantile([0.1, 0.5, 0.9]).unstack()
    target = by_time["target_mmhg"].median()

    # --- cell 4: the figure
    fig, (ax_map, ax_rate) = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
    t_min = band.index / 60.0
    for ax, col, unit in (
        (ax_map, "map_true_mmhg", "MAP (mmHg)"),
        (ax_rate, "rate_ml_h", "rate (ml/h)"),
    ):
        ax.fill_between(t_min, band[(col, 0.1)], band[(col, 0.9)], alpha=0.3, label="10-90 %")
        ax.plot(t_min, band[(col, 0.5)], label="median")
        ax.set_ylabel(unit)
    ax_map.plot(t_min, target.to_numpy(), "k--", label="target")
    ax_map.legend(loc="lower right")
    ax_rate.set_xlabel("time (min)")
    fig.suptitle(f"{result.controller} on {result.scenario}: {result.n_patients} patients")
    fig.savefig(args.out, dpi=80)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
