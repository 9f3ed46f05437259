"""Stability/performance certificates of a frozen closed loop over the parameter box: the common
result type and inputs (:mod:`~synthesis.certificates.interface`), the conditioning state
transform and the working-set growth loop. ``wirtinger`` certifies the shipped ``smith`` family;
``jensen`` is used only for ``theorem3`` artifacts.
"""
