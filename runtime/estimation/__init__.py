"""Online estimation of the scheduling parameters K, T, τ, and the sources that schedule on it.

On the shipped path when ``pressor run --schedule estimated`` (or ``validated``) is chosen. Pure and
light: imports only the standard library, ``contracts``, ``baselines`` and, below it,
``runtime.core`` (no numpy on the hot path, no solver, no simulator). Modules:

:mod:`runtime.estimation.gate`
    Which MAP samples may enter the estimator (NaN, quality bits, range, spikes, flatlines).
:mod:`runtime.estimation.noise`
    The monitor noise of a window mean, read from the data.
:mod:`runtime.estimation.estimator`
    The delay-bank Kalman estimator (method, prior, health check: see its docstring); its report
    is :class:`runtime.core.estimate.Estimate`.
:mod:`runtime.estimation.settings`
    The estimator's tuning (:class:`~runtime.estimation.settings.EstimatorSettings`: units,
    ranges, defaults) and the nominal patient and design box it defaults to.
:mod:`runtime.estimation.sources`
    The estimated scheduling source and :func:`~runtime.estimation.sources.make_schedule` (the
    oracle and nominal sources and the protocol are :mod:`runtime.core.scheduling`).
:mod:`runtime.estimation.validated`, :mod:`runtime.estimation.validation`
    The opt-in validated source and the held-out model bank it validates on.
"""
