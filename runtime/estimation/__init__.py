"""Online estimation of the scheduling parameters K, T, τ and the scheduling sources.

Pure and light: imports only the standard library, ``contracts`` and ``baselines`` (no numpy on the
hot path, no solver, no simulator). Modules:

:mod:`runtime.estimation.gate`
    Which MAP samples may enter the estimator (NaN, quality bits, range, spikes, flatlines).
:mod:`runtime.estimation.noise`
    The monitor noise of a window mean, read from the data.
:mod:`runtime.estimation.estimator`
    The delay-bank Kalman estimator (method, prior, health check: see its docstring).
:mod:`runtime.estimation.estimate`
    Its report (:class:`~runtime.estimation.estimate.Estimate`): values, uncertainty, health.
:mod:`runtime.estimation.schedule`
    The scheduling sources the runtime plugs in: oracle, nominal, estimated.
"""
