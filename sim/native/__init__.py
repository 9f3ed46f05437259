"""Compiled twins of the simulation's pure arithmetic, used in process when a C compiler works.

Each twin gives the same IEEE double results as the Python it stands in for (checked bit for bit
in the tests), so a trial's records are the same bytes with or without it
(:mod:`plumbing.native_build`: flags, cache, ``PRESSOR_NATIVE=off``). The bedside runtime never
uses them: ``pressor run`` steps the hash-checked Python module.
"""
