"""One BLAS thread for the synthesis commands and cohort trials (set before numpy is first imported).

The ``pressor`` dispatcher (:mod:`pressor.cli`) calls :func:`single_blas_thread` for ``synth``,
``verify`` and ``trial`` before it imports their stage module: importing that module already loads
numpy, so a call from inside the command would come too late and silently do nothing. The
benchmarks that run cohorts call it first thing, for the same reason.

The synthesis and verification work on many small dense matrices (eigenvalues of 100-250 square
generators, 6-22 square LMI blocks); OpenBLAS' thread pool does not speed those up and its
waiting threads make them many times slower (docs/notes/benchmarks.md, "Design measurements").
Clarabel's
sparse factorisation keeps its own threads. A trial's patients each make a few tiny BLAS calls (the
patient's discretisation, the metrics), after which OpenBLAS' idle threads spin on another core.
An explicit ``OPENBLAS_NUM_THREADS`` is respected.
"""

from __future__ import annotations

import os
import sys

__all__ = ["single_blas_thread"]


def single_blas_thread() -> bool:
    """Ask OpenBLAS for one thread unless the environment already chose a number.

    Returns
    -------
    bool
        True if it takes effect (numpy not imported yet and no explicit setting), else False.
    """
    if "numpy" in sys.modules or "OPENBLAS_NUM_THREADS" in os.environ:
        return False
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    return True
