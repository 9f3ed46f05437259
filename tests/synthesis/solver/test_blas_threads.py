"""The synthesis commands ask OpenBLAS for one thread only when they still can and may."""

from __future__ import annotations

import os
import subprocess
import sys

PROBE = (
    "import os{pre}\n"
    "from pressor.synthesis.solver.blas_threads import single_blas_thread\n"
    "print(single_blas_thread(), os.environ.get('OPENBLAS_NUM_THREADS'))\n"
)


def _probe(pre: str = "", **env: str) -> str:
    base = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    out = subprocess.run(
        [sys.executable, "-c", PROBE.format(pre=pre)],
        env={**base, **env},
        capture_output=True,
        text=True,
        check=True,
    )
    return out.stdout.strip()


def test_sets_one_thread_before_numpy_is_imported() -> None:
    assert _probe() == "True 1"


def test_leaves_an_explicit_setting_alone() -> None:
    assert _probe(OPENBLAS_NUM_THREADS="2") == "False 2"


def test_does_nothing_once_numpy_is_loaded() -> None:
    assert _probe(pre="; import numpy") == "False None"
