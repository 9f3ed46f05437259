"""The ``smith`` family (the shipped design): a closed-form scheduled Smith-predictor + PI law
(:mod:`~pressor.synthesis.families.smith.law`), designed and certified by the Wirtinger analysis LMI in
K-scaled coordinates (:mod:`~pressor.synthesis.families.smith.design`), registered as a family object
(:mod:`~pressor.synthesis.families.smith.family`).
"""
