"""Benchmarks that print their figures (docs/notes/benchmarks.md lists them with their last results).

Each runs from the project root as a module, ``python -m benchmarks.NAME [--help]``, so the
project's packages and the shared test doubles (``tests.support``) import without path set-up.
"""
