"""What every stage of pressor must agree on, in one leaf package.

The controller protocol, the metric definitions, the fault catalogue and its spec syntax, the
integrity rule of a generated module, and what every command line shares: the usage-error exit
(:mod:`contracts.usage`) and atomic file output (:mod:`contracts.files`). Standard library and
numpy only; it imports no stage (``synthesis``, ``codegen``, ``runtime``, ``hil_sim``, ``link``),
every stage may import it.
"""
