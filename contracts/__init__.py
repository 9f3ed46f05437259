"""What every stage of pressor must agree on, in one leaf package.

The controller protocol, the metric definitions, the fault catalogue and its spec syntax, and the
integrity rule of a generated module. Standard library and numpy only; it imports no stage
(``synthesis``, ``codegen``, ``runtime``, ``hil_sim``, ``link``), every stage may import it.
"""
