"""Certify the Smith predictor in the LPV controller class with the Wirtinger-based analysis LMI.

Builds the scheduled Smith predictor (:class:`pressor.synthesis.families.smith.law.SmithLPV`) at every point
of a grid over the shipped design's box, closes it with the shipped plant model and weights (so γ
compares with the shipped design's, :func:`pressor.synthesis.families.smith.design.smith_loops`), and runs
the design's own certificate (the Wirtinger analysis LMI conditioned by the nominal point's frozen
certificate) through the research entry :func:`research.synthesis_forms.certify_smith_form`, which takes
the formulation options the shipped :func:`pressor.synthesis.families.smith.design.certify_smith` does not:
all rate vertices or one LMI per point, working set, coupling, parameters of P, coordinates. Prints
the certificate verdict, γ, the smallest re-checked margin, wall and CPU time and peak RSS (figures
in docs/notes/certificate-structure.md)::

    python -m research.smith_certificate --loop-gain 2 --grid 3,3,3 [--p-dependence quadratic]
    python -m research.smith_certificate --loop-gain 2 --grid 5,5,5 --working-set 27 --gamma-cap
    15

``--working-set K`` imposes the LMI at K spread points and re-checks every point and rate vertex
(the verdict covers the whole grid either way); ``--gamma-cap G`` solves the feasibility form (γ ≤
G, largest common margin), whose solution is off the boundary of the points left out; it uses the
Clarabel settings of the shipped feasibility solve (``FEASIBILITY_SOLVER_OPTIONS``: looser gap
tolerances, no iterative refinement), so its margin t and timings can differ slightly from capped
figures measured before that (the verdict is the floating-point re-check either way). ``--rate-form
bound`` is the cheap form (one LMI per point with rate slacks; ``--epsilon 5e-5`` keeps its
minimum-γ solution inside the vertex LMIs, so no back-off solve is needed); ``--coupling per_point``
gives each point its own copy of P, ``--p-params K,tau`` lets P depend on those parameters only.
``--coordinates k_scaled`` uses the K-scaled functional
(:mod:`pressor.synthesis.certificates.wirtinger.k_scaling`: u and û times K, the K rate and r = K(t)/K(t −
τ) as rate coordinates), which certifies loop gain 3::

    python -m research.smith_certificate --loop-gain 3 --grid 5,5,5 --rate-form bound \
        --coordinates k_scaled --gamma-cap 8

``--compare`` first runs the current formulation (every rate vertex, dense coupling, P in every
parameter, ε = 1e-6, plain coordinates, same grid and cap) in a child process and prints the
ratios of wall time, CPU time and peak RSS::

    python -m research.smith_certificate --grid 3,3,3 --rate-form bound --epsilon 5e-5 --compare
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import time
from collections.abc import Callable

import numpy as np


def _progress(t0: float) -> Callable[[str], None]:
    """Progress lines on stderr, stamped with the time since ``t0`` (s)."""

    def report(msg: str) -> None:
        print(f"[{time.perf_counter() - t0:6.1f} s] {msg}", file=sys.stderr, flush=True)

    return report


def main() -> None:
    """Parse the arguments, solve, print one line of figures."""
    from pressor.synthesis.artifact import default_artifact_path, load_artifact
    from pressor.synthesis.families.smith.design import nominal_centre, smith_loops
    from pressor.synthesis.families.smith.law import SmithLPV
    from pressor.synthesis.problem.reconstruct import scaling_of
    from research.synthesis_forms import certify_smith_form

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--loop-gain", type=float, default=2.0, help="K*Kc = T/lambda (default 2)")
    ap.add_argument("--grid", default="3,3,3", help="points per axis K,T,tau (default 3,3,3)")
    ap.add_argument(
        "--p-dependence", default="quadratic", choices=("constant", "affine", "quadratic")
    )
    ap.add_argument(
        "--working-set",
        type=int,
        default=None,
        metavar="K",
        help="impose the LMI at K spread points, re-check all (default: every point)",
    )
    ap.add_argument(
        "--gamma-cap",
        type=float,
        default=None,
        metavar="G",
        help="feasibility form: gamma <= G, maximise the common margin (default: minimise gamma)",
    )
    ap.add_argument(
        "--epsilon",
        type=float,
        default=1e-6,
        help="strictness margin of every LMI, scaled units (default 1e-6)",
    )
    ap.add_argument("--rate-form", default="vertex", choices=("vertex", "bound"))
    ap.add_argument("--coupling", default="dense", choices=("dense", "per_point"))
    ap.add_argument(
        "--p-params",
        default="K,T,tau",
        help="parameters P depends on, comma-separated from K,T,tau (default all)",
    )
    ap.add_argument(
        "--compare",
        action="store_true",
        help="also run the current formulation (vertex, dense, P in K,T,tau, epsilon 1e-6) in a child process",
    )
    ap.add_argument(
        "--coordinates",
        default="plain",
        choices=("plain", "k_scaled"),
        help="functional in the loop's own states or with u, u-hat scaled by K (default plain)",
    )
    ap.add_argument("--progress", action="store_true", help="solver progress lines on stderr")
    args = ap.parse_args()
    names = ("K", "T", "tau")
    if not set(args.p_params.split(",")) <= set(names):
        ap.error(f"--p-params={args.p_params!r}: comma-separated names from K,T,tau")
    p_params = [names.index(v) for v in args.p_params.split(",")]
    reference = None
    if args.compare:
        argv = [a for a in sys.argv[1:] if a != "--compare"]
        argv += ["--rate-form", "vertex", "--coupling", "dense", "--p-params", "K,T,tau"]
        argv += ["--epsilon", "1e-6", "--coordinates", "plain"]  # the last occurrence wins
        reference = _figures(
            subprocess.run(
                [sys.executable, "-m", "research.smith_certificate", *argv],
                check=True,
                capture_output=True,
                text=True,
            ).stdout
        )
    if args.working_set is not None and args.working_set < 1:
        ap.error(f"--working-set={args.working_set}: need an integer >= 1")
    counts = [int(v) for v in args.grid.split(",")]
    if len(counts) != 3 or min(counts) < 2:
        ap.error(f"--grid={args.grid!r}: need three integers >= 2")

    art = load_artifact(default_artifact_path())
    model, box = art.model_config, np.asarray(art.box, dtype=float)
    axes = [np.linspace(box[i, 0], box[i, 1], counts[i]) for i in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    law = SmithLPV(args.loop_gain, model.omega, model.lambda_)
    t0, cpu0 = time.perf_counter(), time.process_time()
    res = certify_smith_form(
        smith_loops(law, model, pts),
        pts,
        nominal_centre(law, model),
        model,
        scaling_of(art),
        gamma_cap=args.gamma_cap,
        progress=_progress(t0) if args.progress else None,
        p_dependence=args.p_dependence,
        rate_form=args.rate_form,
        epsilon=args.epsilon,
        working_set=args.working_set,
        coupling=args.coupling,
        p_params=p_params,
        coordinates=args.coordinates,
    )
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    rss_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6  # kB on Linux
    print(
        f"loop gain {args.loop_gain:g}, grid {args.grid}, P {args.p_dependence} in "
        f"{args.p_params}, {args.coordinates}, {args.rate_form}/{args.coupling}, epsilon {args.epsilon:g}, working set {args.working_set}, "
        f"gamma cap {args.gamma_cap}: certified={res.certified} status={res.status} "
        f"gamma={res.gamma} min margin={np.min(res.margins):.3g} LMIs={res.n_lmis} "
        f"wall={wall:.1f} s cpu={cpu:.1f} s peak RSS={rss_gb:.2f} GB "
        f"(shipped design gamma {art.gamma:.2f})"
    )
    for note in res.notes:
        print(f"  {note}")
    if reference is not None:
        print(
            f"current formulation (vertex/dense, P in K,T,tau): gamma={reference['gamma']} "
            f"certified={reference['certified']} wall={reference['wall']:.1f} s "
            f"cpu={reference['cpu']:.1f} s peak RSS={reference['rss']:.2f} GB; ratio "
            f"current/this: wall {reference['wall'] / wall:.1f}x, cpu "
            f"{reference['cpu'] / cpu:.1f}x, peak RSS {reference['rss'] / rss_gb:.1f}x"
        )


def _figures(line: str) -> dict[str, float | str]:
    """gamma, certified, wall (s), cpu (s), peak RSS (GB) from this script's summary line."""
    fields = dict(tok.split("=", 1) for tok in line.splitlines()[0].split() if "=" in tok)
    return {
        "gamma": fields["gamma"],
        "certified": fields["certified"],
        "wall": float(fields["wall"]),
        "cpu": float(fields["cpu"]),
        "rss": float(fields["RSS"]),
    }


if __name__ == "__main__":
    main()
