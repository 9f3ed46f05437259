"""What every stage of pressor must agree on, in one leaf package.

The controller protocol, the metric definitions, the fault catalogue and its spec syntax, the
integrity rule of a generated module and the range check every input validator shares. Standard
library and numpy only; it imports no stage (``synthesis``, ``codegen``, ``runtime``, ``hil_sim``,
``link``), every stage may import it. The process plumbing the commands share (usage errors, atomic
files, parallel tasks) is :mod:`plumbing`, not a contract.
"""
