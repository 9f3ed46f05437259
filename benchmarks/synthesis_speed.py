"""Synthesis and verification benchmark: what ``pressor synth`` runs vs the straightforward forms.

Each case runs in its own subprocess (so peak memory is its own ``ru_maxrss``), all in the same
run so machine load is comparable. Prints wall time, peak RSS and the outcome of each case, and the
ratio of the straightforward formulation to the one ``pressor synth`` / ``pressor verify`` use.
The cases follow the controller family of the config (synth) and of the artifact (verify),
:mod:`pressor.synthesis.families.registry`, and come from the research entry :mod:`research.synthesis_forms`:

* synth: :func:`research.synthesis_forms.synth_case` — what ``pressor synth`` solves (the shipped family:
  the Wirtinger analysis on the design grid in the rate-bound form, one LMI per point, one solve
  at the strictness ``DESIGN_EPSILON``; the Theorem-3 family: the batched sparse formulation,
  :func:`pressor.synthesis.families.theorem3.lmi_solve.solve`) vs the straightforward formulation of the
  same design (every rate / delay-ratio vertex as its own LMI; the naive per-point cvxpy
  formulation, :mod:`research.synthesis_forms.naive_lmi`);
* verify: :func:`pressor.synthesis.verification.verify.verify_artifact` (check (a) as ``pressor verify``
  runs it: one capped rate-bound solve over the dense grid; the Theorem-3 family: a working set) vs
  :func:`research.synthesis_forms.verify_all_points_at_once` (every dense point and rate vertex as its own
  LMI in one solve).

Every case runs with one KKT backend forced (:mod:`pressor.synthesis.solver.kkt`), once per backend of
``--kkt`` (default: each of them), so the table gives the time per backend; the straightforward
cases run on the first backend only.

::

    python -m benchmarks.synthesis_speed [--config FILE.toml] [--grid 3,3,3] [--rate-terms vertices]
                                   [--artifact FILE.npz] [--only synth|verify] [--skip-naive]
                                   [--kkt faer,qdldl]

``--rate-terms vertices`` benchmarks the paper's 2³-vertex Theorem-3 synthesis (8 LMIs per node)
instead of the design's setting; ``--skip-naive`` leaves out both straightforward cases (they are
the slow ones).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from typing import Any


def _child(kind: str, args: argparse.Namespace) -> None:
    from pressor.synthesis.solver.kkt import kkt_chain

    with kkt_chain([args.kkt]):
        row = _case(kind, args)
    print(json.dumps({"kind": f"{kind}[{args.kkt}]", **row}))


def _case(kind: str, args: argparse.Namespace) -> dict[str, Any]:
    t0 = time.perf_counter()
    if kind.startswith("verify"):
        from pressor.synthesis.artifact import default_artifact_path, load_artifact
        from pressor.synthesis.verification.verify import verify_artifact
        from research.synthesis_forms import verify_all_points_at_once

        art = load_artifact(args.artifact or default_artifact_path())
        verify = verify_all_points_at_once if kind == "verify-all" else verify_artifact
        rep = verify(art).to_dict()
        lmi = rep["analysis_lmi"]
        row = {
            "outcome": f"passed={rep['passed']} certified={lmi['certified']}",
            "detail": f"{lmi['n_lmis']} LMIs re-checked, analysis {lmi['solve_time_s']:.1f} s",
        }
    else:
        from dataclasses import replace

        from pressor.synthesis.problem.config_toml import load_config
        from research.synthesis_forms import synth_case

        cfg = load_config(args.config)
        if args.grid:
            cfg = cfg.with_grid(tuple(int(v) for v in args.grid.split(",")))
        if args.rate_terms:  # a [solver] setting: only a family with a synthesis LMI reads it
            cfg = replace(cfg, solver=replace(cfg.solver, rate_terms=args.rate_terms))
        row = synth_case(cfg, straightforward=kind == "naive")
    row["wall_s"] = time.perf_counter() - t0
    row["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return row


def _run(kind: str, argv: list[str], method: str) -> dict:
    cmd = [
        sys.executable,
        "-m",
        "benchmarks.synthesis_speed",
        "--child",
        kind,
        f"--kkt={method}",
        *argv,
    ]
    # one BLAS thread, as pressor synth / verify set it (pressor.synthesis.solver.blas_threads), for every
    # case
    env = {**os.environ, "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "1")}
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False, env=env)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        return {
            "kind": f"{kind}[{method}]",
            "error": proc.stderr.strip().splitlines()[-1:] or ["?"],
        }
    return json.loads(lines[-1])


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--config")
    ap.add_argument("--grid")
    ap.add_argument("--rate-terms", choices=["bound", "vertices"])
    ap.add_argument("--artifact", help="artifact for the verify cases (default: the shipped one)")
    ap.add_argument("--only", choices=["synth", "verify"])
    ap.add_argument("--skip-naive", action="store_true")
    ap.add_argument(
        "--kkt",
        default="faer,qdldl",
        help="KKT backends to time, comma-separated (default: faer,qdldl; each case per backend)",
    )
    ap.add_argument(
        "--child", choices=["synth", "naive", "verify", "verify-all"], help=argparse.SUPPRESS
    )
    args = ap.parse_args()
    if args.child:
        _child(args.child, args)
        return 0
    argv = [
        f"--{k.replace('_', '-')}={v}"
        for k, v in vars(args).items()
        if k in ("config", "grid", "rate_terms", "artifact") and v
    ]
    # (what pressor uses, the straightforward formulation it is compared with)
    pairs = [("synth", "naive"), ("verify", "verify-all")]
    if args.only:
        pairs = [p for p in pairs if p[0] == args.only]
    methods = args.kkt.split(",")
    print(f"{'case':<20}{'wall s':>9}{'peak MB':>9}  outcome / detail")
    for used, straight in pairs:
        first = methods[0]
        rows = [_run(used, argv, first)]
        rows += [] if args.skip_naive else [_run(straight, argv, first)]
        rows += [_run(used, argv, m) for m in methods[1:]]
        for r in rows:
            if "error" in r:
                print(f"{r['kind']:<20} failed: {r['error']}")
                continue
            print(
                f"{r['kind']:<20}{r['wall_s']:>9.1f}{r['peak_rss_mb']:>9.0f}  {r['outcome']}; "
                f"{r['detail']}"
            )
        if not args.skip_naive and all("error" not in r for r in rows[:2]):
            u, s = rows[:2]
            print(
                f"{s['kind']} / {u['kind']}: wall {s['wall_s'] / u['wall_s']:.2f}x, "
                f"peak memory {s['peak_rss_mb'] / u['peak_rss_mb']:.2f}x"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
