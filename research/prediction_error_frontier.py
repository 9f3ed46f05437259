"""How far in τ the analysis in prediction-error coordinates certifies each law, per rate bound.

Usage::

    python -m research.prediction_error_frontier                  # the table in the docs
    python -m research.prediction_error_frontier --config research/designs/wide_delay.toml \
        --law trapezoid --verify

Each row runs :func:`pressor.synthesis.certificates.wirtinger.prediction_error.certify` (the Wirtinger
analysis on a 3 x 3 grid of T and τ, the box's corners and midpoints) for the shipped box's K floor (0.15
mmHg/(ml/h)), T box 100-700 s, τ from 10 s, loop gain 3 and filter (Ω = Λ = 0.1 1/s), with the
law, τ̄ and rates of the row. ``--verify`` also runs the check ``pressor verify`` runs on a
design: the same analysis on a 5 x 5 grid with γ capped at twice the design's. ``--config``
takes one design file's box, rates, loop gain and filter instead. The figures are in
docs/notes/certificate-structure.md, §5.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace

from pressor.synthesis.certificates.wirtinger.prediction_error import (
    LAWS,
    PredictionErrorBox,
    certify,
)
from pressor.synthesis.problem.config_toml import load_config

#: |dK/dt| (mmHg/(ml/h)/s), |dT/dt| (s/s), |dτ/dt| (s/s)
RATES = {
    "shipped": (6e-4, 0.06, 0.1),
    "delay60": (2e-4, 0.03, 0.05),
    "slow": (5e-5, 0.01, 0.01),
}
TAUS_S = (45.0, 60.0, 100.0, 150.0, 200.0, 300.0)
VERIFY_GRID = (5, 5)
VERIFY_CAP_FACTOR = 2.0


def _row(label: str, box: PredictionErrorBox, verify: bool) -> str:
    design = certify(box)
    gamma = f"{design.gamma:.3f}" if design.certified and design.gamma is not None else "no"
    cells = [label, box.law, f"{box.tau_range_s[1]:g}", gamma, f"{design.solve_time_s:.1f}"]
    if verify:
        check = "-"
        if design.certified and design.gamma is not None:
            cap = VERIFY_CAP_FACTOR * design.gamma
            dense = certify(box, *VERIFY_GRID, gamma_cap=cap)
            check = f"{'passed' if dense.certified else 'failed'} ({dense.solve_time_s:.1f} s)"
        cells.append(check)
    return "| " + " | ".join(cells) + " |"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", help="certify this design file only (TOML)")
    parser.add_argument("--law", choices=LAWS, default=None, help="one law only (default: both)")
    parser.add_argument("--verify", action="store_true", help="also the 5 x 5 check at 2x γ")
    args = parser.parse_args(argv)
    laws = (args.law,) if args.law else LAWS
    head = "| rates K/T/τ | law | τ̄ (s) | γ (3 x 3) | time (s) |"
    print(head + (" 5 x 5 at 2γ |" if args.verify else ""))
    print("|---" * (6 if args.verify else 5) + "|")
    if args.config:
        base = PredictionErrorBox.from_config(load_config(args.config))
        for law in laws:
            print(_row(args.config, replace(base, law=law), args.verify), flush=True)
        return 0
    for law in laws:
        for name, rates in RATES.items():
            for tau in TAUS_S:
                box = PredictionErrorBox(
                    0.15, (100.0, 700.0), (10.0, tau), rates, 3.0, 0.1, 0.1, law=law
                )
                print(_row(name, box, args.verify), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
