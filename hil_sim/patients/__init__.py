"""Simulated patients: the seed paper's nonlinear patient (the default), the independent PK/PD,
phenylephrine and norepinephrine models (their shared delay line and counter-regulation:
:mod:`~pressor.hil_sim.patients.drug_patient`), the :class:`~pressor.hil_sim.patients.patient_model.PatientModel`
protocol a plugin satisfies, seeded cohort draws, sensitivity scaling, and the true-MAP log.

Imports no other part of ``hil_sim``: the bottom layer.
"""
