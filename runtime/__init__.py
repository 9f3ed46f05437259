"""The bedside runtime: fixed-rate loop, supervisor, MAVLink serial link and rerun recorder.

Never imports ``synthesis``, ``cvxpy`` or ``hil_sim`` (docs/ARCHITECTURE.md): a bedside box has no solver
and no simulated patient. Keep this ``__init__`` free of imports so that light modules
(``contracts.controller``, ``baselines.pi``, ``contracts.metrics``) load without serial or rerun.
"""
