"""Benchmarks that print their figures (benchmarks/README.md: each one, its command, last result).

Each runs from the project root as a module, ``python -m benchmarks.NAME [--help]``, so the
project's packages and the shared test doubles (``tests.support``) import without path set-up.

Importing this package pins OpenBLAS to one thread (unless ``OPENBLAS_NUM_THREADS`` is set), as
``pressor synth``, ``verify`` and ``trial`` do: the figures are per core, and idle OpenBLAS threads
spinning on another core after each tiny BLAS call would count against them
(:mod:`pressor.synthesis.solver.blas_threads`). It runs before any benchmark module loads numpy.
"""

from pressor.synthesis.solver.blas_threads import single_blas_thread

single_blas_thread()
