"""Online estimation of the scheduling parameters K, T, τ, and the sources that schedule on it.

On the shipped path when ``pressor run --schedule estimated`` (or ``validated``) is chosen. Pure and
light: imports only the standard library, ``contracts``, ``baselines`` and, below it,
``pressor.runtime.core`` (no numpy on the hot path, no solver, no simulator). Modules:

:mod:`pressor.runtime.estimation.gate`
    Which MAP samples may enter the estimator (NaN, quality bits, range, spikes, flatlines).
:mod:`pressor.runtime.estimation.noise`
    The monitor noise of a window mean, read from the data.
:mod:`pressor.runtime.estimation.estimator`
    The delay-bank Kalman estimator (method, prior, health check: see its docstring); its report
    is :class:`pressor.runtime.core.estimate.Estimate`.
:mod:`pressor.runtime.estimation.settings`
    The estimator's tuning (:class:`~pressor.runtime.estimation.settings.EstimatorSettings`: units,
    ranges, defaults) and the nominal patient and design box it defaults to.
:mod:`pressor.runtime.estimation.sources`
    The estimated scheduling source and :func:`~pressor.runtime.estimation.sources.make_schedule` (the
    oracle and nominal sources and the protocol are :mod:`pressor.runtime.core.scheduling`).
:mod:`pressor.runtime.estimation.validated`, :mod:`pressor.runtime.estimation.validation`
    The opt-in validated source and the held-out model bank it validates on.
:mod:`pressor.runtime.estimation.cautious`
    The cautious start (the default source of a design on a log-K scale): K̂ from the population's
    most sensitive patient down, on evidence.
:mod:`pressor.runtime.estimation.caution`
    Each drug's settings of the cautious start, and its dose ceiling's formula.
:mod:`pressor.runtime.estimation.unit_lag`
    The unit-gain patients the cautious start reads its evidence against.
:mod:`pressor.runtime.estimation.design_envelope`
    What a generated module declares: its box, certified rates, population and syringe.
"""
