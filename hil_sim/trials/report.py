"""A self-contained HTML report of a cohort trial, with its plots and the data they were drawn from.

``write_report(out_dir, ...)`` writes, into ``out_dir``:

* ``report.html`` — one file, every plot embedded as a PNG (no network, no other file needed to
  read it): the trial's identity, the paired comparison table, and the figures;
* ``trajectories_<CONTROLLER>.npz`` — per controller, the per-patient trajectories the envelopes
  were drawn from: ``t_s`` (n,), ``map_true_mmhg``, ``target_mmhg``, ``rate_ml_h`` (patients × n),
  and ``patient_seed`` (patients,).

Figures: envelopes over time of the true MAP's distance from the target (with the ±5 mmHg band) and
of the delivered infusion (median with the p10–p90 band over the reachable patients, one colour per
controller), the distribution of each headline metric per controller, and a paired
scatter of the first controller's IAE against each other controller's (points below the diagonal are
patients the first controller served better). Matplotlib draws them with its non-interactive Agg
backend, so no display is needed. Same inputs, same bytes: the PNGs carry no timestamp.
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np

from pressor.hil_sim.trials.paired import stat_cells
from pressor.hil_sim.trials.trial import controller_dir_name
from pressor.plumbing.files import write_atomic

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)

#: per-patient trajectory arrays a report needs, each (patients × ticks) except t_s (ticks,)
TRAJECTORY_KEYS = ("t_s", "map_true_mmhg", "target_mmhg", "rate_ml_h", "patient_seed")
#: headline metrics whose distributions are drawn (name, axis label)
DISTRIBUTION_METRICS = (
    ("iae_mmhg_s", "IAE (mmHg·s)"),
    ("time_in_band_pct", "time within ±5 mmHg (%)"),
    ("step_overshoot_pct", "step overshoot (%)"),
    ("drug_total_ml", "drug used (ml)"),
)
_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e")


def _png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, metadata={"Software": None})
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _envelope_figure(
    trajectories: Mapping[str, Mapping[str, np.ndarray]],
    records: Mapping[str, Sequence[Mapping[str, Any]]],
) -> str:
    fig, (ax_map, ax_rate) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    for colour, (name, tr) in zip(_COLOURS, trajectories.items(), strict=False):
        t_min = np.asarray(tr["t_s"]) / 60.0
        reachable = np.array([r["reachable"] for r in records[name]], dtype=bool)
        if not reachable.any():
            continue
        # MAP as its distance from the target: patients' baselines differ by tens of mmHg, so
        # absolute MAP bands show the cohort's spread, not the control
        error = np.asarray(tr["map_true_mmhg"]) - np.asarray(tr["target_mmhg"])
        for ax, rows in ((ax_map, error), (ax_rate, np.asarray(tr["rate_ml_h"]))):
            p10, p50, p90 = np.nanpercentile(rows[reachable], [10, 50, 90], axis=0)
            ax.fill_between(t_min, p10, p90, color=colour, alpha=0.2, linewidth=0)
            ax.plot(t_min, p50, color=colour, label=f"{name} (median, p10–p90)")
    ax_map.axhline(0.0, color="k", linestyle="--", linewidth=1)
    for band in (-5.0, 5.0):
        ax_map.axhline(band, color="k", linestyle=":", linewidth=0.8)
    ax_map.set_ylabel("true MAP − target (mmHg)")
    ax_rate.set_ylabel("infusion delivered (ml/h)")
    ax_rate.set_xlabel("time (min)")
    ax_map.legend(loc="lower right", fontsize=8)
    ax_map.set_title("MAP and infusion over the cohort (reachable patients)")
    fig.tight_layout()
    return _png(fig)


def _distribution_figure(records: Mapping[str, Sequence[Mapping[str, Any]]]) -> str:
    fig, axes = plt.subplots(1, len(DISTRIBUTION_METRICS), figsize=(12, 3.6))
    names = list(records)
    for ax, (metric, label) in zip(axes, DISTRIBUTION_METRICS, strict=True):
        data = [
            [r[metric] for r in records[n] if r["reachable"] and r.get(metric) is not None]
            for n in names
        ]
        ax.boxplot(data, tick_labels=names, showfliers=True)
        ax.set_title(label, fontsize=9)
    fig.suptitle("per-patient metrics (reachable patients)")
    fig.tight_layout()
    return _png(fig)


def _paired_figure(records: Mapping[str, Sequence[Mapping[str, Any]]]) -> str:
    names = list(records)
    head = names[0]
    fig, axes = plt.subplots(1, len(names) - 1, figsize=(4.2 * (len(names) - 1), 4), squeeze=False)
    for ax, other in zip(axes[0], names[1:], strict=True):
        pairs = [
            (a["iae_mmhg_s"], b["iae_mmhg_s"])
            for a, b in zip(records[head], records[other], strict=True)
            if a["reachable"] and b["reachable"] and None not in (a["iae_mmhg_s"], b["iae_mmhg_s"])
        ]
        x = np.array([p[1] for p in pairs])
        y = np.array([p[0] for p in pairs])
        ax.scatter(x, y, s=12)
        hi = float(max(x.max(), y.max())) if pairs else 1.0
        ax.plot([0, hi], [0, hi], "k:", linewidth=1)
        ax.set_xlabel(f"{other} IAE (mmHg·s)")
        ax.set_ylabel(f"{head} IAE (mmHg·s)")
        ax.set_title(f"{head} vs {other}, one point per patient", fontsize=9)
    fig.tight_layout()
    return _png(fig)


def _comparison_table(comparison: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> str:
    rows = []
    for pair, metrics in comparison.items():
        for metric, s in metrics.items():
            cells = [pair, metric, *stat_cells(s)]
            rows.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>")
    head = "".join(
        f"<th>{h}</th>"
        for h in ("pair", "metric", "n", "win rate %", "median ratio", "median diff", "Wilcoxon p")
    )
    return f"<table><tr>{head}</tr>{''.join(rows)}</table>"


def write_report(
    out_dir: Path,
    title: str,
    records: Mapping[str, Sequence[Mapping[str, Any]]],
    trajectories: Mapping[str, Mapping[str, np.ndarray]],
    comparison: Mapping[str, Mapping[str, Mapping[str, Any]]],
) -> Path:
    """Write ``report.html`` and the per-controller trajectory files; return the report's path.

    Parameters
    ----------
    out_dir
        The trial's output directory (created if missing).
    title
        One line naming the trial (scenario, cohort seed, size).
    records
        Controller spec -> per-patient records, in the order the user named the controllers.
    trajectories
        Controller spec -> arrays named by :data:`TRAJECTORY_KEYS`.
    comparison
        :func:`pressor.hil_sim.trials.paired.compare_controllers` of ``records`` (empty for one controller).
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, tr in trajectories.items():
        buf = io.BytesIO()
        np.savez_compressed(buf, **{k: np.asarray(tr[k]) for k in TRAJECTORY_KEYS})
        write_atomic(out_dir / f"trajectories_{controller_dir_name(name)}.npz", buf.getvalue())
    figures = [_envelope_figure(trajectories, records), _distribution_figure(records)]
    if len(records) > 1:
        figures.append(_paired_figure(records))
    body = [f"<h1>{html.escape(title)}</h1>"]
    if comparison:
        body += ["<h2>Paired comparison (reachable patients)</h2>", _comparison_table(comparison)]
    body += [f'<p><img alt="figure" src="data:image/png;base64,{png}"></p>' for png in figures]
    page = (
        "<!DOCTYPE html><html><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title><style>"
        "body{font-family:sans-serif;max-width:1100px;margin:auto}"
        "table{border-collapse:collapse;font-size:12px}td,th{border:1px solid #ccc;padding:2px 6px}"
        "</style></head><body>" + "\n".join(body) + "</body></html>\n"
    )
    path = out_dir / "report.html"
    write_atomic(path, page)
    return path
