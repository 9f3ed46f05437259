"""Step-time and allocation benchmark of the generated controller (Python float, Python integer, C).

Usage: python -m benchmarks.controller_step [--steps N] [--alloc-steps N]
Prints median and p99 step time (µs) per implementation and the tracemalloc net growth over
``--alloc-steps`` steps (default 10^6) of the Python float module.
"""

from __future__ import annotations

import argparse
import ctypes
import importlib.util
import random
import shutil
import subprocess
import tempfile
import time
import tracemalloc
from pathlib import Path

from pressor.codegen import pipeline as pl

MODULE = Path(pl.REPO_ROOT) / "runtime" / "generated" / "lpv_map_controller.py"


def _load(path: Path):
    spec = importlib.util.spec_from_file_location("bench_gen", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _inputs(n: int) -> list[tuple[float, float, float, float, float]]:
    rng = random.Random(0)
    return [
        (
            70 + 20 * rng.random(),
            90.0,
            rng.uniform(0.2, 1.1),
            rng.uniform(90, 210),
            rng.uniform(5, 50),
        )
        for _ in range(n)
    ]


def _timeit(step, inputs) -> tuple[float, float]:
    times = []
    clock = time.perf_counter_ns
    for args in inputs:
        t0 = clock()
        step(*args)
        times.append(clock() - t0)
    times.sort()
    return times[len(times) // 2] / 1e3, times[int(0.99 * len(times))] / 1e3


def _c_step_times(n: int) -> tuple[float, float] | None:
    gcc = shutil.which("gcc")
    if not gcc or not pl.DEFAULT_ARTIFACT.is_file():
        return None
    with tempfile.TemporaryDirectory() as tmp:
        pl.generate(pl.DEFAULT_ARTIFACT, "c", tmp)
        bench = Path(tmp) / "bench.c"
        bench.write_text(
            "#define _POSIX_C_SOURCE 199309L\n#include <time.h>\n#include <stdint.h>\n"
            '#include "lpv_map_controller.h"\n'
            "static lpvmap_state_t s;\n"
            "int64_t run(int32_t n, double *ns_out) {\n"
            "  struct timespec a, b; int32_t k; double acc = 0;\n"
            "  lpvmap_reset(&s);\n"
            "  for (k = 0; k < n; ++k) {\n"
            "    clock_gettime(CLOCK_MONOTONIC, &a);\n"
            "    acc += lpvmap_step(&s, 70.0 + (k % 97) * 0.2, 90.0, 0.3 + (k % 89) * 0.008,\n"
            "                       100.0 + (k % 83), 10.0 + (k % 31));\n"
            "    clock_gettime(CLOCK_MONOTONIC, &b);\n"
            "    ns_out[k] = (double)(b.tv_sec - a.tv_sec) * 1e9 + (double)(b.tv_nsec - a.tv_nsec);\n"
            "  }\n  return (int64_t)acc;\n}\n"
        )
        lib = Path(tmp) / "libbench.so"
        subprocess.run(
            [gcc, "-std=c99", "-O2", "-shared", "-fPIC", "-o", str(lib),
             str(Path(tmp) / "lpv_map_controller.c"), str(bench)],
            check=True,
        )  # fmt: skip
        so = ctypes.CDLL(str(lib))
        buf = (ctypes.c_double * n)()
        so.run.restype = ctypes.c_int64
        so.run(ctypes.c_int32(n), buf)
        # clock_gettime itself costs ~20 ns; report raw figures (an upper bound)
        times = sorted(buf)
        return times[n // 2] / 1e3, times[int(0.99 * n)] / 1e3


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=100_000)
    ap.add_argument("--alloc-steps", type=int, default=1_000_000)
    args = ap.parse_args()
    mod = _load(MODULE)
    inputs = _inputs(args.steps)
    for name, fixed in (("python float", False), ("python integer", True)):
        med, p99 = _timeit(mod.Controller(fixed_point=fixed).step, inputs)
        print(f"{name:16s} median {med:7.2f} us   p99 {p99:7.2f} us   ({args.steps} steps)")
    c = _c_step_times(args.steps)
    if c:
        print(f"{'C (-O2)':16s} median {c[0]:7.3f} us   p99 {c[1]:7.3f} us   (incl. clock_gettime)")
    ctrl = mod.Controller()
    step = ctrl.step
    for a in inputs[:1000]:
        step(*a)
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    n = len(inputs)
    for k in range(args.alloc_steps):
        step(*inputs[k % n])
    grown = tracemalloc.get_traced_memory()[0] - base
    tracemalloc.stop()
    print(f"allocation growth over {args.alloc_steps} float steps: {grown} bytes")


if __name__ == "__main__":
    main()
