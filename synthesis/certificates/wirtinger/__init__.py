"""The Wirtinger-based analysis LMI in K-scaled coordinates (on the shipped path: it certifies
every ``smith`` artifact in ``pressor synth`` and check (a) of ``pressor verify``).
"""
