"""What the tests share and are not tests: doubles, an independent device, plugins, helpers.

Importable as ``tests.support.NAME`` from the project root (pytest's ``pythonpath``; the
benchmarks run as ``python -m benchmarks.NAME`` from the root).
"""
