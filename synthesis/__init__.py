"""Offline synthesis of the delay-dependent LPV MAP controller (paper's Theorem 3, cvxpy + Clarabel).

Imports no I/O-heavy package (no serial, no rerun); nothing in ``runtime/`` imports this package.
"""
