"""The ``theorem3`` family (the alternative, not shipped): the full-order controller synthesised
by the paper's Theorem-3 LMIs (layout, assembly, solve, (λ2, λ3) line search), certified in
``pressor verify`` by the Jensen (Theorem-1) analysis of :mod:`pressor.synthesis.certificates.jensen`.
"""
