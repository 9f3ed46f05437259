"""Synthesis benchmark: the batched sparse formulation vs the naive per-point cvxpy formulation.

Each formulation runs in its own subprocess (so peak memory is its own ``ru_maxrss``) on the same
design (default: the shipped design config and grid). Prints wall time (build + solve), peak RSS,
γ, solver status and iterations for both, and the ratios.

    python benchmarks/synthesis.py [--config FILE.toml] [--grid 3,3,3] [--rate-terms vertices]
                                   [--skip-naive]

``--rate-terms vertices`` benchmarks the paper's 2³-vertex formulation (8 LMIs per node) instead
of the design's setting.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time


def _child(kind: str, config: str | None, grid: str | None, rate_terms: str | None) -> None:
    # this script is itself called synthesis.py: keep its directory from shadowing the package
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != here]
    sys.modules.pop("synthesis", None)
    from synthesis import lmi
    from synthesis.config import load_config

    cfg = load_config(config)
    if grid:
        cfg = cfg.with_grid(tuple(int(v) for v in grid.split(",")))
    if rate_terms:
        from dataclasses import replace

        cfg = replace(cfg, solver=replace(cfg.solver, rate_terms=rate_terms))
    t0 = time.perf_counter()
    prob = lmi.make_problem(cfg)
    if kind == "batched":
        res = lmi.solve(prob)
    else:
        from synthesis.lmi_naive import solve_naive

        res = solve_naive(prob)
    wall = time.perf_counter() - t0
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(
        json.dumps(
            {
                "kind": kind,
                "grid": list(cfg.grid_points),
                "wall_s": wall,
                "build_s": res.build_time_s,
                "solve_s": res.solve_time_s,
                "peak_rss_mb": peak_mb,
                "gamma": res.gamma,
                "status": res.status,
                "iterations": res.iterations,
                "n_lmi": res.n_lmi,
                "lmi_size": res.lmi_size,
            }
        )
    )


def _run(kind: str, config: str | None, grid: str | None, rate_terms: str | None) -> dict:
    cmd = [sys.executable, __file__, "--child", kind]
    if rate_terms:
        cmd += ["--rate-terms", rate_terms]
    if config:
        cmd += ["--config", config]
    if grid:
        cmd += ["--grid", grid]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        return {"kind": kind, "error": proc.stderr.strip().splitlines()[-1:] or ["?"]}
    return json.loads(lines[-1])


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--config")
    ap.add_argument("--grid")
    ap.add_argument("--rate-terms", choices=["bound", "vertices"])
    ap.add_argument("--skip-naive", action="store_true")
    ap.add_argument("--child", choices=["batched", "naive"], help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        _child(args.child, args.config, args.grid, args.rate_terms)
        return 0
    rows = [_run("batched", args.config, args.grid, args.rate_terms)]
    if not args.skip_naive:
        rows.append(_run("naive", args.config, args.grid, args.rate_terms))
    hdr = f"{'formulation':<12}{'grid':>9}{'LMIs':>6}{'build s':>9}{'solve s':>9}{'wall s':>9}{'peak MB':>9}{'gamma':>10}{'iters':>7}  status"
    print(hdr)
    for r in rows:
        if "error" in r:
            print(f"{r['kind']:<12} failed: {r['error']}")
            continue
        print(
            f"{r['kind']:<12}{'x'.join(map(str, r['grid'])):>9}{r['n_lmi']:>6}{r['build_s']:>9.2f}"
            f"{r['solve_s']:>9.1f}{r['wall_s']:>9.1f}{r['peak_rss_mb']:>9.0f}{r['gamma']:>10.4f}"
            f"{str(r['iterations']):>7}  {r['status']}"
        )
    if len(rows) == 2 and all("error" not in r for r in rows):
        b, n = rows
        print(
            f"naive / batched: build {n['build_s'] / b['build_s']:.0f}x, wall {n['wall_s'] / b['wall_s']:.2f}x, "
            f"peak memory {n['peak_rss_mb'] / b['peak_rss_mb']:.2f}x; gamma difference "
            f"{abs(n['gamma'] - b['gamma']) / b['gamma'] * 100:.3f} %"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
