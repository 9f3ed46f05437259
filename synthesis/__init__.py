"""Offline design of the delay-dependent LPV MAP controller (cvxpy + Clarabel).

Controller families are registered in :mod:`synthesis.family`. The shipped one, ``smith``
(:mod:`synthesis.smith_family`), is the scheduled Smith predictor + PI in the paper's controller
class, a closed-form law certified by the Wirtinger-based analysis LMI in K-scaled coordinates;
the alternative, ``theorem3`` (:mod:`synthesis.theorem3`), is the full-order controller
synthesised by the paper's Theorem-3 LMIs. Both write the same artifact format
(:mod:`synthesis.artifact`), checked by the same independent verifier (:mod:`synthesis.verify`).
Other formulations of the certificate, for benchmarks only, are in :mod:`synthesis.research`.

Imports no I/O-heavy package (no serial, no rerun); nothing in ``runtime/`` imports this package.
"""
