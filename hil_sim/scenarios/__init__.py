"""Scenarios: the named TOML files beside :mod:`pressor.hil_sim.scenarios.scenario` (target step, monitor,
pump, disturbances, faults), their loader and validation, the disturbance shapes and the fault
injectors (world faults, link faults).
"""
