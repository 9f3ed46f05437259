"""How every command runs, not what it computes: the process plumbing the stages share.

The usage-error exit of a command line (:mod:`pressor.plumbing.usage`), atomic file output
(:mod:`pressor.plumbing.files`) and running independent tasks locally or on a Dask cluster
(:mod:`pressor.plumbing.parallel`). Standard library only (``distributed`` is imported only when a Dask
scheduler is named); it imports no other package of ours, and every stage may import it.
"""
