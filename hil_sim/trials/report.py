"""A self-contained HTML report of a cohort trial, with its plots and the data they were drawn from.

``write_report(out_dir, ...)`` writes, into ``out_dir``:

* ``report.html`` — one file, every plot embedded as a PNG (no network, no other file needed to
  read it): the trial's identity, the paired comparison table, and the figures;
* ``trajectories_<CONTROLLER>.npz`` — per controller, the per-patient trajectories the envelopes
  were drawn from: ``t_s`` (n,), ``map_true_mmhg``, ``target_mmhg``, ``rate_ml_h`` (patients × n),
  and ``patient_seed`` (patients,).

The page hides no patient: a "Patients" section counts, per controller, the patients, the
reachable ones (the figures and the paired table), the unreachable ones, each listed with why
(:func:`pressor.hil_sim.trials.words.unreachable_lines`), and the unstable ones; the paired table
gives wins / ties / losses (a tie is no loss).

Figures: envelopes over time of the true MAP's distance from the target (with the ±5 mmHg band) and
of the delivered infusion (median with the p10–p90 band over the reachable patients, one colour and
one line style per controller, the medians drawn over every band so none hides another), the
distribution of each headline metric per controller (percentages on a fixed 0–100 % axis, the
others on an axis of at least :data:`MIN_SPAN`, so noise is not magnified), and a paired
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

from pressor.hil_sim.trials.paired import STAT_HEADS, stat_cells
from pressor.hil_sim.trials.trial import controller_dir_name
from pressor.hil_sim.trials.words import (
    UNREACHABLE_MEANS,
    metric_label,
    patient_counts,
    unreachable_lines,
)
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
#: one line style per controller, so overlapping medians stay told apart (cycled past five)
LINE_STYLES = ("-", "--", "-.", ":", (0, (5, 1, 1, 1, 1, 1)))
#: opacity of a controller's p10–p90 band: every band and every median shows through the others
BAND_ALPHA = 0.15
#: metrics drawn on a fixed axis (their unit's whole range)
FIXED_AXIS = {"time_in_band_pct": (0.0, 100.0)}
#: the smallest axis span per metric (its unit): a spread smaller than this is drawn as small
MIN_SPAN = {"iae_mmhg_s": 500.0, "step_overshoot_pct": 10.0, "drug_total_ml": 10.0}


def _png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, metadata={"Software": None})
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def envelope_figure(
    trajectories: Mapping[str, Mapping[str, np.ndarray]],
    records: Mapping[str, Sequence[Mapping[str, Any]]],
) -> Any:
    """The MAP-error and infusion envelopes (a matplotlib figure; :func:`_png` renders it)."""
    fig, (ax_map, ax_rate) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    counts = []
    for i, (name, tr) in enumerate(trajectories.items()):
        colour, style = _COLOURS[i % len(_COLOURS)], LINE_STYLES[i % len(LINE_STYLES)]
        t_min = np.asarray(tr["t_s"]) / 60.0
        reachable = np.array([r["reachable"] for r in records[name]], dtype=bool)
        counts.append(f"{name} {int(reachable.sum())} of {reachable.size}")
        if not reachable.any():
            continue
        # MAP as its distance from the target: patients' baselines differ by tens of mmHg, so
        # absolute MAP bands show the cohort's spread, not the control
        error = np.asarray(tr["map_true_mmhg"]) - np.asarray(tr["target_mmhg"])
        for ax, rows in ((ax_map, error), (ax_rate, np.asarray(tr["rate_ml_h"]))):
            p10, p50, p90 = np.nanpercentile(rows[reachable], [10, 50, 90], axis=0)
            ax.fill_between(t_min, p10, p90, color=colour, alpha=BAND_ALPHA, linewidth=0, zorder=1)
            # the medians above every band (zorder), each in its own style
            ax.plot(
                t_min,
                p50,
                color=colour,
                linestyle=style,
                linewidth=1.6,
                zorder=3 + i,
                label=f"{name} (median, p10–p90)",
            )
    ax_map.axhline(0.0, color="k", linestyle="--", linewidth=1, zorder=2)
    for band in (-5.0, 5.0):
        ax_map.axhline(band, color="k", linestyle=":", linewidth=0.8, zorder=2)
    ax_map.set_ylabel("true MAP − target (mmHg)")
    ax_rate.set_ylabel("infusion delivered (ml/h)")
    per_ml_h = _dose_per_ml_h(records)
    if per_ml_h is not None:  # the same infusion in µg/kg/min on the right-hand axis
        factor, label = per_ml_h
        dose = ax_rate.secondary_yaxis(
            "right", functions=(lambda r: r * factor, lambda d: d / factor)
        )
        dose.set_ylabel(label)
    ax_rate.set_xlabel("time (min)")
    if ax_map.get_lines()[0].get_label().endswith("p10–p90)"):
        ax_map.legend(loc="lower right", fontsize=8)
    else:  # no controller had a reachable patient: say so where the envelopes would be
        ax_map.text(0.5, 0.5, "no reachable patient", transform=ax_map.transAxes, ha="center")
    ax_map.set_title(f"MAP and infusion, reachable patients ({'; '.join(counts)})")
    fig.tight_layout()
    return fig


def _dose_per_ml_h(records: Mapping[str, Sequence[Mapping[str, Any]]]) -> tuple[float, str] | None:
    """µg/kg/min per ml/h of the records' syringe and weight, and the dose axis' label; ``None``
    when the records carry no ``infusion`` or their controllers' syringes differ."""
    seen = {
        (r["infusion"]["drug"], r["infusion"]["concentration_ug_ml"], r["infusion"]["weight_kg"])
        for recs in records.values()
        for r in recs
        if "infusion" in r
    }
    if len(seen) != 1:
        return None
    drug, c, w = seen.pop()
    return c / (60.0 * w), f"dose (µg/kg/min; {drug} {c:g} µg/ml, {w:g} kg)"


def infusion_section(records: Mapping[str, Sequence[Mapping[str, Any]]]) -> str:
    """The report's "Infusion" section: per controller the drug, syringe and weight (a reference
    weight said as such) and the median over every patient of the mean and peak infusion in ml/h
    and µg/kg/min; ``""`` when the records carry no ``infusion``."""
    from pressor.hil_sim.trials.outputs import infusion_summary

    heads = (
        "controller",
        "drug",
        "syringe (µg/ml)",
        "weight (kg)",
        "mean rate (ml/h)",
        "mean dose (µg/kg/min)",
        "peak rate (ml/h)",
        "peak dose (µg/kg/min)",
    )
    rows = []
    for name, recs in records.items():
        inf = infusion_summary(recs)
        if inf is None:
            continue
        weight = f"{inf['weight_kg']:g}" + ("" if inf["weight_given"] else " (reference)")
        cells = [name, inf["drug"], f"{inf['concentration_ug_ml']:g}", weight] + [
            "-" if inf[f"median_{k}"] is None else f"{inf[f'median_{k}']:.3g}"
            for k in (
                "mean_rate_ml_h",
                "mean_dose_ug_kg_min",
                "peak_rate_ml_h",
                "peak_dose_ug_kg_min",
            )
        ]
        rows.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>")
    if not rows:
        return ""
    head = "".join(f"<th>{html.escape(h)}</th>" for h in heads)
    return (
        "<h2>Infusion (median over all patients)</h2><p>The mean rate is the drug given over the"
        " run; doses in µg/kg/min are per the weight shown (the 70 kg reference adult the patient"
        " models count when no weight was given).</p>"
        f"<table><tr>{head}</tr>{''.join(rows)}</table>"
    )


def distribution_figure(records: Mapping[str, Sequence[Mapping[str, Any]]]) -> Any:
    """The per-patient distributions of :data:`DISTRIBUTION_METRICS` (a matplotlib figure), each on
    a fixed axis (:data:`FIXED_AXIS`) or one of at least :data:`MIN_SPAN`."""
    fig, axes = plt.subplots(1, len(DISTRIBUTION_METRICS), figsize=(12, 3.6))
    names = list(records)
    for ax, (metric, label) in zip(axes, DISTRIBUTION_METRICS, strict=True):
        data = [
            [r[metric] for r in records[n] if r["reachable"] and r.get(metric) is not None]
            for n in names
        ]
        ax.boxplot(data, tick_labels=names, showfliers=True)
        ax.set_title(label, fontsize=9)
        lo, hi = _axis_range(metric, [v for column in data for v in column])
        ax.set_ylim(lo, hi)
    n = {name: patient_counts(records[name])["reachable"] for name in names}
    total = max(len(r) for r in records.values())
    fig.suptitle(
        "per-patient metrics, reachable patients ("
        + "; ".join(f"{name} {k} of {total}" for name, k in n.items())
        + ")"
    )
    fig.tight_layout()
    return fig


def _axis_range(metric: str, values: Sequence[float]) -> tuple[float, float]:
    """The y range of ``metric``'s panel: :data:`FIXED_AXIS` padded by 2 % of it, else the data's
    range from 0 (or its minimum, if negative) widened to :data:`MIN_SPAN`, padded by 5 %."""
    if metric in FIXED_AXIS:
        lo, hi = FIXED_AXIS[metric]
        pad = 0.02 * (hi - lo)
        return lo - pad, hi + pad
    lo = min([0.0, *values])
    hi = max([lo, *values])
    hi = max(hi, lo + MIN_SPAN.get(metric, 1.0))
    pad = 0.05 * (hi - lo)
    return lo - (pad if lo < 0.0 else 0.0), hi + pad


def _envelope_figure(
    trajectories: Mapping[str, Mapping[str, np.ndarray]],
    records: Mapping[str, Sequence[Mapping[str, Any]]],
) -> str:
    return _png(envelope_figure(trajectories, records))


def _distribution_figure(records: Mapping[str, Sequence[Mapping[str, Any]]]) -> str:
    return _png(distribution_figure(records))


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
            cells = [pair, metric_label(metric), *stat_cells(s)]
            rows.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>")
    head = "".join(f"<th>{html.escape(h)}</th>" for h in ("pair", "metric", *STAT_HEADS))
    return f"<table><tr>{head}</tr>{''.join(rows)}</table>"


def patients_section(records: Mapping[str, Sequence[Mapping[str, Any]]]) -> str:
    """The report's "Patients" section: per controller the patients, reachable, unreachable and
    unstable counts; each unreachable patient with why (once when every controller's run has the
    same ones); what "unreachable" means."""
    parts = ["<h2>Patients</h2>", "<ul>"]
    for name, recs in records.items():
        c = patient_counts(recs)
        parts.append(
            f"<li>{html.escape(name)}: {c['patients']} patients: {c['reachable']} reachable"
            f" (in the figures and the paired table), {c['unreachable']} unreachable (listed"
            f" below), {c['unstable']} unstable</li>"
        )
    parts.append("</ul>")
    per = {name: unreachable_lines(recs) for name, recs in records.items()}
    if any(per.values()):
        parts.append(f"<p>{html.escape(UNREACHABLE_MEANS)}.</p>")
        if len({tuple(v) for v in per.values()}) == 1:
            groups = {"every controller": next(iter(per.values()))}
        else:
            groups = per
        for who, lines in groups.items():
            if not lines:
                continue
            parts.append(f"<p>Unreachable ({html.escape(who)}):</p><ul class='unreachable'>")
            parts += [f"<li>{html.escape(line)}</li>" for line in lines]
            parts.append("</ul>")
    return "\n".join(parts)


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
    body = [f"<h1>{html.escape(title)}</h1>", patients_section(records)]
    infusion = infusion_section(records)
    if infusion:
        body.append(infusion)
    if comparison:
        body += [
            "<h2>Paired comparison (patients reachable under both)</h2>",
            "<p>wins / ties / losses: the patients the first controller served better, equally,"
            " worse; ratio and difference: first against second, in the metric's unit.</p>",
            _comparison_table(comparison),
        ]
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
