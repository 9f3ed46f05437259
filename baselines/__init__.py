"""The baseline control laws every comparison shows: a fixed PI and a scheduled Smith predictor.

Small, pure, standard-library controllers (the :class:`pressor.contracts.controller.Controller` protocol).
The runtime runs them, the simulator's trials run them, and ``pressor verify`` simulates them in
its nominal step, so they live beside the contracts rather than in any one stage. Imports only
``contracts``.
"""
