"""The design problem every family shares (on the shipped path): the plant model and its design
configuration (TOML), the closed-loop delay system, the coordinate scaling, the reference prefilter,
the ρ-basis of the LPV coefficients and the controller at a frozen ρ of any artifact
(:mod:`pressor.synthesis.problem.reconstruct`, used by every family, ``pressor verify`` and codegen).
"""
