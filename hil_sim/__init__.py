"""The software-in-the-loop world: nonlinear patient, infusion pump, MAP sensor, scenarios, trials.

Runs on the far side of the serial link; may import the link protocol from ``runtime``.
"""
