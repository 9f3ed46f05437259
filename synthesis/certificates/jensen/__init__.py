"""The Jensen (the paper's Theorem-1) analysis LMI, used only for ``theorem3`` artifacts (check (a)
of ``pressor verify`` and the theorem3 design stage); not on the shipped path.
"""
