"""Stability/performance certificates of a frozen closed loop over the parameter box: the common
result type and inputs (:mod:`~pressor.synthesis.certificates.interface`), the conditioning state
transform and the solve-and-recheck driver with its working set
(:mod:`~pressor.synthesis.certificates.working_set`). ``wirtinger`` certifies the shipped ``smith`` family;
``jensen`` is used only for ``theorem3`` artifacts.
"""
