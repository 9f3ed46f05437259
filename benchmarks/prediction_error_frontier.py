"""How far in τ the prediction-error certificate reaches, per rate bound and T box.

Usage::

    python -m benchmarks.prediction_error_frontier                       # the table in the docs
    python -m benchmarks.prediction_error_frontier --config benchmarks/designs/wide_delay.toml

Each row runs :func:`synthesis.certificates.prediction_error.certify` (9 T design points, every
LMI re-checked in numpy at 33) on the shipped box's K floor (0.15 mmHg/(ml/h)), loop gain 3 and
filter (Ω = Λ = 0.1 1/s), with the τ box, T box and rates of the row. ``--config`` certifies one
design file instead (its K floor, T and τ boxes, rates, loop gain and filter). The figures are in
docs/CERTIFICATE-STRUCTURE.md, §5.
"""

from __future__ import annotations

import argparse
import sys

from synthesis.certificates.prediction_error import PredictionErrorBox, certify
from synthesis.problem.config_toml import load_config

#: |dK/dt| (mmHg/(ml/h)/s), |dT/dt| (s/s), |dτ/dt| (s/s): the shipped design's, delay60's, between
RATES = {
    "shipped": (6e-4, 0.06, 0.1),
    "4e-4/0.06/0.1": (4e-4, 0.06, 0.1),
    "delay60": (2e-4, 0.03, 0.05),
}
TAUS_S = (45.0, 60.0, 100.0, 150.0, 200.0, 300.0, 400.0)
T_BOXES_S = ((100.0, 400.0), (100.0, 700.0))


def _row(label: str, box: PredictionErrorBox) -> str:
    cert = certify(box)
    gamma = f"{cert.gamma:.3f}" if cert.gamma is not None else "-"
    margin = f"{min(cert.margins):.1e}" if cert.gamma is not None else "-"
    verdict = "certified" if cert.certified else f"not certified ({cert.status})"
    return (
        f"| {label} | {box.t_range_s[0]:g}-{box.t_range_s[1]:g} | {box.tau_max_s:g} | "
        f"{verdict} | {gamma} | {margin} | {cert.solve_time_s:.1f} |"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", help="certify this design file only (TOML)")
    args = parser.parse_args(argv)
    print("| rates K/T/τ | T box (s) | τ̄ (s) | result | γ | margin | time (s) |")
    print("|---|---|---|---|---|---|---|")
    if args.config:
        print(_row(args.config, PredictionErrorBox.from_config(load_config(args.config))))
        return 0
    for t_box in T_BOXES_S:
        for name, rates in RATES.items():
            for tau in TAUS_S:
                box = PredictionErrorBox(0.15, t_box, tau, rates, 3.0, 0.1, 0.1)
                print(_row(name, box), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
