"""What every stage of pressor must agree on, in one leaf package.

The controller protocol, the metric definitions, the fault catalogue and its spec syntax, the
integrity rule of a generated module, and what every command line shares: the usage-error exit
(:mod:`contracts.usage`), atomic file output (:mod:`contracts.files`) and running independent
tasks locally or on a Dask cluster (:mod:`contracts.parallel`). Standard library and numpy only
(``distributed`` is imported only when a Dask scheduler is named); it imports no stage (``synthesis``, ``codegen``, ``runtime``, ``sim``, ``link``),
every stage may import it.
"""
